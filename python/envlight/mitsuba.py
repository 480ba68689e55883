"""envlight inside Mitsuba 3: the emitter type ``"envlight"``.

``register()`` adds it for the active Mitsuba variant; a scene then uses it where it
would use ``envmap``::

    import mitsuba as mi
    import envlight.mitsuba
    mi.set_variant("llvm_ad_rgb")
    envlight.mitsuba.register()
    scene = mi.load_dict({..., "sky": {"type": "envlight", "filename": "sky.exr"}})

Parameters, in Mitsuba's style:

- ``filename`` (or ``bitmap``, a ``mi.Bitmap``): a latitude-longitude map, read by
  Mitsuba (its file resolver and formats) as linear RGB;
- ``scale`` (float, 1): radiance multiplier; ``to_world`` (transform): as ``envmap``'s,
  the map's frame is ``envmap``'s (y up);
- ``sampling``: ``"light"`` (the default: density ∝ the map's importance) or
  ``"product"`` (density ∝ the map's importance × cos⁺ at the interaction's
  geometric normal ``it.n``, from envlight's product tables; an interaction
  without a normal, in a medium, is sampled as ``"light"``). Product samples
  follow the hemisphere of ``it.n``: light reaching a surface from behind its
  geometric normal (transmission, a two-sided material seen from the back) is left
  to BSDF sampling, which Mitsuba's integrators weight against the emitter's by MIS;
- envlight's options: ``sampler`` (``"inversion"``), ``density``
  (``"piecewise-bilinear"``, the default: bilinear over the lookup's nodes, as
  ``envmap``'s warp is; ``"piecewise-constant"``), ``mapping`` (``"equirectangular"``,
  ``"equal-area"``) and ``lookup`` (``"node"``, the default, ``envmap``'s convention:
  rows as nodes from pole to pole; ``"bilinear"``, texel centres; ``"nearest"``).

Every query (``sample_direction``, ``pdf_direction``, ``eval``, ``eval_direction``)
is Dr.Jit code over the light's exported tables (docs/gpu-tables.md), so it traces
into Mitsuba's kernels in symbolic mode; ``register()`` changes no Dr.Jit flag.
RGB variants only (``scalar_rgb``, ``llvm_*_rgb``, ``cuda_*_rgb``).
"""

import importlib
import os

import numpy as np

from . import _native
from ._drjit_product import TableProduct
from ._drjit_tables import TableLight

__all__ = ["register"]

SAMPLINGS = ("light", "product")
# The light's option names come from the library. The Dr.Jit port evaluates the
# inversion sampler's tables only (alias is not ported, hierarchical not
# exported: see _drjit_tables), so the emitter takes that one of them.
SAMPLERS = tuple(s for s in _native.SAMPLERS if s == "inversion")
DENSITIES = _native.DENSITIES
MAPPINGS = _native.MAPPINGS
LOOKUPS = _native.LOOKUPS

_classes = {}


def _mitsuba():
    try:
        import mitsuba
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("envlight.mitsuba needs Mitsuba 3: pip install mitsuba") from e
    return mitsuba


def register():
    """Registers the emitter type ``"envlight"`` for Mitsuba's active variant.

    Raises RuntimeError when no variant is set or the variant is not an RGB one."""
    mi = _mitsuba()
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("envlight.mitsuba.register(): no Mitsuba variant is set; call mitsuba.set_variant() first")
    if not mi.is_rgb or mi.is_polarized:
        raise RuntimeError(
            f'envlight.mitsuba.register(): variant "{variant}" is not supported; '
            "the envlight emitter runs in RGB variants (scalar_rgb, llvm_ad_rgb, cuda_ad_rgb)"
        )
    cls = _classes.get(variant)
    if cls is None:
        cls = _classes[variant] = _emitter_class(mi)
    mi.register_emitter("envlight", lambda props: cls(props))


def _choice(props, name, choices, default):
    if name not in props:
        return default
    value = props[name]
    if not isinstance(value, str) or value not in choices:
        allowed = ", ".join(f'"{c}"' for c in choices)
        raise ValueError(f'envlight emitter: parameter "{name}" must be one of {allowed}, got {value!r}')
    return value


def _load_rgb(mi, props):
    """The map as an (H, W, 3) float32 array of linear RGB, and its name."""
    has_file = ("filename" in props)
    has_bitmap = ("bitmap" in props)
    if has_file and has_bitmap:
        raise ValueError('envlight emitter: cannot specify both "bitmap" and "filename"')
    if has_bitmap:
        bitmap = props["bitmap"]
        if not isinstance(bitmap, mi.Bitmap):
            raise TypeError('envlight emitter: property "bitmap" must be a mitsuba.Bitmap')
        name = "<Bitmap>"
    elif has_file:
        filename = str(props["filename"])
        resolver = mi.file_resolver() if hasattr(mi, "file_resolver") else mi.Thread.thread().file_resolver()
        path = str(resolver.resolve(filename))
        if not os.path.isfile(path):
            raise FileNotFoundError(f'envlight emitter: environment map "{filename}" not found')
        try:
            bitmap = mi.Bitmap(path)
        except Exception as e:
            raise OSError(f'envlight emitter: cannot read environment map "{filename}": {e}') from e
        name = filename
    else:
        raise ValueError('envlight emitter: a "filename" (or "bitmap") parameter is required')
    bitmap = bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
    rgb = np.array(bitmap, dtype=np.float32, copy=True).reshape(bitmap.height(), bitmap.width(), 3)
    if rgb.shape[0] < 2 or rgb.shape[1] < 2:
        raise ValueError(f'envlight emitter: "{name}": the environment map must be at least 2x2 pixels, got '
                         f"{rgb.shape[1]}x{rgb.shape[0]}")
    return rgb, name


def _clamp_negative(mi, rgb, name):
    """Negative texels (lossy codecs leave them) clamped to 0, with a warning that
    counts them (docs/design.md §5); NaN and infinite texels are left for the light
    to refuse."""
    negative = (rgb < 0).any(axis=2)
    count = int(negative.sum())
    if count:
        mi.Log(mi.LogLevel.Warn, f'envlight emitter: "{name}": {count} texels with negative channels clamped to 0 '
               f"(most negative {float(rgb.min()):g})")
        rgb = np.where(rgb < 0, np.float32(0), rgb)
    return rgb


def _emitter_class(mi):
    import drjit as dr

    # The variant's own module: `mitsuba.X` follows whichever variant is active
    # when it is read, but an emitter must keep the types of the variant it was
    # registered for.
    mv = importlib.import_module(f"mitsuba.{mi.variant()}")
    emitter_ptr = getattr(mv, "EmitterPtr", None)

    class EnvlightEmitter(mv.Emitter):
        """envlight's environment light as a Mitsuba emitter (see envlight.mitsuba)."""

        def __init__(self, props):
            super().__init__(props)
            self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.SpatiallyVarying
            self.sampling = _choice(props, "sampling", SAMPLINGS, "light")
            self.options = {
                "sampler": _choice(props, "sampler", SAMPLERS, "inversion"),
                "density": _choice(props, "density", DENSITIES, "piecewise-bilinear"),
                "mapping": _choice(props, "mapping", MAPPINGS, "equirectangular"),
                "lookup": _choice(props, "lookup", LOOKUPS, "node"),
            }
            scale = props.get("scale", 1.0)
            if not isinstance(scale, (int, float)) or not np.isfinite(scale) or scale < 0:
                raise ValueError(f'envlight emitter: "scale" must be a finite number >= 0, got {scale!r}')
            rgb, self.name = _load_rgb(mi, props)
            rgb = _clamp_negative(mi, rgb, self.name)
            # Scalar variants' Float is a Python float, which traverse() cannot
            # update in place: a one-element array there.
            jit = dr.is_jit_v(mv.Float)
            self.m_scale = mv.Float(float(scale)) if jit else dr.scalar.ArrayXf([float(scale)])
            self.m_data = mv.TensorXf(rgb)
            # The emitter's own copy of to_world (read by Mitsuba's base class), so
            # that traverse() can expose it and an update reaches the queries.
            self.m_to_world = self.world_transform()
            self._build(rgb)

        def _build(self, rgb):
            """Builds the CPU light over rgb and the Dr.Jit evaluator of its tables.
            In JIT variants the radiance is read from ``m_data`` itself, so Dr.Jit
            differentiates eval() with respect to the map (the sampling tables are
            constants, as envmap's are)."""
            try:
                self.light = _native.EnvironmentLight.from_array(np.ascontiguousarray(rgb, np.float32), **self.options)
                self.tables = TableLight(self.light.gpu_tables(), mv)
                self.product = None
                if self.sampling == "product":
                    self.product = TableProduct(self.light.product_tables(), self.tables, mv)
            except ValueError as e:
                raise ValueError(f'envlight emitter: "{self.name}": {e}') from e
            if self.tables.jit:
                self.tables.texels = self.m_data.array

        def traverse(self, callback):
            super().traverse(callback)
            callback.put("scale", self.m_scale, mi.ParamFlags.Differentiable)
            callback.put("data", self.m_data, mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous)
            callback.put("to_world", self.m_to_world, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys=[]):
            """A new map (``data``) rebuilds the light and its tables (checked as a
            new file would be); ``scale`` and ``to_world`` are read as they are."""
            if not keys or "data" in keys:
                shape = tuple(self.m_data.shape)
                if len(shape) != 3 or shape[2] != 3:
                    raise ValueError(f"envlight emitter: data has shape {shape}, expected (height, width, 3)")
                if shape[0] < 2 or shape[1] < 2:
                    raise ValueError(f"envlight emitter: data is {shape[1]}x{shape[0]}, at least 2x2 is needed")
                rgb = np.array(self.m_data, dtype=np.float32).reshape(shape)
                clamped = _clamp_negative(mi, rgb, self.name)
                if clamped is not rgb:
                    self.m_data = mv.TensorXf(clamped)
                self._build(clamped)
            super().parameters_changed(keys)

        def _scale(self):
            return self.m_scale if self.tables.jit else float(self.m_scale[0])

        # -- frames: Mitsuba's envmap frame (y up) ↔ envlight's (z up) ---------------

        def _to_light(self, d_world):
            d = self.m_to_world.inverse() @ d_world
            # envmap's local (x, y, z) is envlight's (y, z, −x).
            return -d.z, d.x, d.y

        def _from_light(self, x, y, z):
            return self.m_to_world @ mv.Vector3f(y, z, -x)

        def _frames(self):
            """(to_world, to_light) over component triples, for TableLight.sample: the
            world direction as a Vector3f stores it, so that pdf_direction of a
            sampled direction finds the cell it was drawn in."""

            def to_world(x, y, z):
                d = self._from_light(x, y, z)
                return d.x, d.y, d.z

            def to_light(x, y, z):
                return self._to_light(mv.Vector3f(x, y, z))

            return to_world, to_light

        # -- queries ----------------------------------------------------------------------

        def _has_normal(self, it):
            return dr.squared_norm(it.n) > 0.0

        def _sample(self, it, sample):
            """((x, y, z), pdf, rgb, valid) of the emitter's sampling strategy."""
            if self.product is None:
                return self.tables.sample(sample.x, sample.y, self._frames())
            n = self._to_light(it.n)
            if not self.tables.jit:
                if self._has_normal(it):
                    return self.product.sample(*n, sample.x, sample.y, self._frames())
                return self.tables.sample(sample.x, sample.y, self._frames())
            # Light samples only where there is no normal (an interaction in a
            # medium), in a symbolic branch: the other lanes do not pay for them.
            def flat(sample):
                (x, y, z), pdf, (r, g, b), valid = sample
                return x, y, z, pdf, r, g, b, valid

            x, y, z, pdf, r, g, b, valid = dr.if_stmt(
                args=(sample.x, sample.y, n[0], n[1], n[2]),
                cond=self._has_normal(it),
                true_fn=lambda u0, u1, nx, ny, nz: flat(self.product.sample(nx, ny, nz, u0, u1, self._frames())),
                false_fn=lambda u0, u1, nx, ny, nz: flat(self.tables.sample(u0, u1, self._frames())),
            )
            return (x, y, z), pdf, (r, g, b), valid

        def sample_direction(self, it, sample, active=True):
            (x, y, z), pdf, rgb, valid = self._sample(it, sample)
            d = mv.Vector3f(x, y, z)
            active = active & valid
            # Mitsuba does not pass the scene to a Python emitter (set_scene is not
            # called), so the shadow ray's end is put far beyond any scene instead
            # of on its bounding sphere: 10⁶ times the point's distance from the
            # origin (+1); the direction of p + d·dist − p keeps f32's precision.
            dist = 1e6 * (1.0 + dr.norm(it.p))
            ds = mv.DirectionSample3f()
            ds.p = it.p + d * dist
            ds.uv = mv.Point2f(0.0)
            ds.n = -d
            ds.time = it.time
            ds.pdf = dr.select(active, pdf, 0.0)
            ds.delta = False
            ds.emitter = emitter_ptr(self) if emitter_ptr is not None else self
            ds.d = d
            ds.dist = dist
            weight = mv.Color3f(rgb[0], rgb[1], rgb[2]) * (self._scale() / dr.select(active, pdf, 1.0))
            return ds, dr.select(active, weight, 0.0)

        def sample_ray(self, time, wavelength_sample, sample2, sample3, active=True):
            # A ray from the scene's bounding disc needs the scene's bounds, which
            # Mitsuba does not give a Python emitter: refuse rather than guess.
            raise NotImplementedError(
                "envlight emitter: sample_ray (light tracing, e.g. the ptracer integrator) is not "
                "supported: Mitsuba does not pass the scene's bounds to a Python emitter; use path, "
                "direct or volpath"
            )

        def sample_wavelengths(self, si, sample, active=True):
            """RGB variants sample no wavelength: an empty set, weighted by the
            radiance arriving along ``-si.wi`` (as ``eval``)."""
            return dr.zeros(type(si.wavelengths)), self._radiance(-si.wi, active)

        def sample_position(self, time, sample, active=True):
            # An environment has no position to sample. In JIT variants Dr.Jit's
            # recording of virtual calls may call this without using the result,
            # so it must not raise there (as envmap does).
            if self.tables.jit:
                return dr.zeros(mv.PositionSample3f), dr.nan
            raise NotImplementedError("envlight emitter: sample_position() is not defined for an environment")

        def pdf_direction(self, it, ds, active=True):
            d = self._to_light(ds.d)
            if self.product is None:
                pdf = self.tables.pdf(*d)
            elif not self.tables.jit:
                pdf = self.product.pdf(*self._to_light(it.n), *d) if self._has_normal(it) else self.tables.pdf(*d)
            else:
                # The light's pdf only where there is no normal, as in _sample.
                n = self._to_light(it.n)
                pdf = dr.if_stmt(
                    args=(d[0], d[1], d[2], n[0], n[1], n[2]),
                    cond=self._has_normal(it),
                    true_fn=lambda x, y, z, nx, ny, nz: self.product.pdf(nx, ny, nz, x, y, z),
                    false_fn=lambda x, y, z, nx, ny, nz: self.tables.pdf(x, y, z),
                )
            return dr.select(active, pdf, 0.0)

        def _radiance(self, d_world, active):
            r, g, b = self.tables.radiance(*self._to_light(d_world))
            return dr.select(active, mv.Color3f(r, g, b) * self._scale(), 0.0)

        def eval(self, si, active=True):
            return self._radiance(-si.wi, active)

        def eval_direction(self, it, ds, active=True):
            return self._radiance(ds.d, active)

        def bbox(self):
            return mv.ScalarBoundingBox3f()

        def to_string(self):
            h, w = self.m_data.shape[0], self.m_data.shape[1]
            return (f'EnvlightEmitter[filename="{self.name}", res={w}x{h}, sampling="{self.sampling}", '
                    + ", ".join(f'{k}="{v}"' for k, v in self.options.items()) + "]")

    return EnvlightEmitter
