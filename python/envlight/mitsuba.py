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
  rows as nodes from pole to pole; ``"bilinear"``, texel centres; ``"nearest"``);
- ``bounds_center`` and ``bounds_radius``: the scene's bounding sphere, which light
  tracing (``sample_ray``, the ``ptracer`` integrator) needs; or call
  ``attach_bounds(scene)`` once the scene is loaded.

Every query (``sample_direction``, ``pdf_direction``, ``eval``, ``eval_direction``,
``sample_ray``, ``sample_wavelengths``) is Dr.Jit code over the light's exported
tables (docs/gpu-tables.md), so it traces into Mitsuba's kernels in symbolic mode;
``register()`` changes no Dr.Jit flag. Every variant: the radiance is RGB, its
luminance (monochrome), or the map upsampled to spectra as ``envmap`` does it
(spectral); polarized variants get unpolarized emission.
"""

import importlib
import os
import weakref

import numpy as np

from . import _native
from ._drjit_product import TableProduct
from ._drjit_tables import TableLight

__all__ = ["attach_bounds", "register"]

SAMPLINGS = ("light", "product")
# The light's option names come from the library. The Dr.Jit port evaluates the
# inversion sampler's tables only (alias is not ported, hierarchical not
# exported: see _drjit_tables), so the emitter takes that one of them.
SAMPLERS = tuple(s for s in _native.SAMPLERS if s == "inversion")
DENSITIES = _native.DENSITIES
MAPPINGS = _native.MAPPINGS
LOOKUPS = _native.LOOKUPS

_classes = {}
# Every envlight emitter alive (see sample_ray).
_emitters = weakref.WeakSet()


def _mitsuba():
    try:
        import mitsuba
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("envlight.mitsuba needs Mitsuba 3: pip install mitsuba") from e
    return mitsuba


def register():
    """Registers the emitter type ``"envlight"`` for Mitsuba's active variant (RGB,
    spectral or monochrome, polarized or not; scalar, LLVM or CUDA).

    Raises RuntimeError when no variant is set."""
    mi = _mitsuba()
    variant = mi.variant()
    if variant is None:
        raise RuntimeError("envlight.mitsuba.register(): no Mitsuba variant is set; call mitsuba.set_variant() first")
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


def _srgb_coefficients(mi, variant, mv, rgb):
    """The spectral upsampling of each texel as envmap makes it: (H·W, 4) float32 of
    the sRGB model's three coefficients of the colour scaled so that its largest
    channel is ½, and that scale (2 · the largest channel).

    Read from an ``envmap`` built over the same texels (its ``data`` holds exactly
    these, with a copy of the opposite edge column on each side), or, where its
    layout is not that one or the active variant is not ``variant`` (``mv``'s),
    computed texel colour by texel colour (about 7 µs each)."""
    h, w, _ = rgb.shape
    data = None
    if mi.variant() == variant:
        try:
            envmap = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(rgb, np.float32))})
            data = np.array(mi.traverse(envmap)["data"], np.float32)
        except Exception:  # pragma: no cover - depends on Mitsuba's version
            data = None
    if data is not None and data.shape == (h, w + 2, 4):
        return np.ascontiguousarray(data[:, 1:w + 1, :]).reshape(-1, 4)
    flat = np.ascontiguousarray(rgb, np.float32).reshape(-1, 3)
    scale = (flat.max(axis=1) * np.float32(2.0)).astype(np.float32)
    norm = flat / np.maximum(np.float32(1e-8), scale)[:, None]
    unique, inverse = np.unique(norm, axis=0, return_inverse=True)
    coefficients = np.array([list(mv.srgb_model_fetch(mv.ScalarColor3f(*map(float, c)))) for c in unique],
                            np.float32).reshape(-1, 3)
    return np.concatenate([coefficients[inverse.reshape(-1)], scale[:, None]], axis=1)


def _bounds_property(props):
    """(centre, radius) from ``bounds_center`` and ``bounds_radius``, or None."""
    has_centre, has_radius = "bounds_center" in props, "bounds_radius" in props
    if not has_centre and not has_radius:
        return None
    if has_centre != has_radius:
        raise ValueError('envlight emitter: "bounds_center" and "bounds_radius" must be given together')
    try:
        centre = tuple(float(x) for x in props["bounds_center"])
    except TypeError:
        centre = ()
    radius = props["bounds_radius"]
    if len(centre) != 3 or not all(np.isfinite(centre)):
        raise ValueError(f'envlight emitter: "bounds_center" must be 3 finite numbers, got {props["bounds_center"]!r}')
    if isinstance(radius, bool) or not isinstance(radius, (int, float)) or not np.isfinite(radius) or radius <= 0:
        raise ValueError(f'envlight emitter: "bounds_radius" must be a finite number > 0, got {radius!r}')
    return centre, float(radius)


def attach_bounds(scene):
    """Gives every ``envlight`` emitter of a loaded ``scene`` the scene's bounding
    sphere, which light tracing (``sample_ray``: the ``ptracer`` integrator) needs
    and Mitsuba does not pass to an emitter written in Python. Call it after
    ``mi.load_dict``/``mi.load_file`` and after any change to the scene's shapes;
    returns how many emitters got the bounds."""
    epsilon = float(_mitsuba().math.RayEpsilon)
    bbox = scene.bbox()
    if bbox.valid():
        sphere = bbox.bounding_sphere()
        centre = tuple(float(x) for x in sphere.center)
        # Widened as Mitsuba's own environment emitters widen it.
        radius = max(epsilon, float(sphere.radius) * (1.0 + epsilon))
    else:
        centre, radius = (0.0, 0.0, 0.0), epsilon
    count = 0
    for emitter in scene.emitters():
        if getattr(emitter, "_is_envlight", False):
            emitter.bounds = (centre, radius)
            count += 1
    return count


def _emitter_class(mi):
    import drjit as dr

    # The variant's own module: `mitsuba.X` follows whichever variant is active
    # when it is read, but an emitter must keep the types of the variant it was
    # registered for.
    variant = mi.variant()
    mv = importlib.import_module(f"mitsuba.{variant}")
    emitter_ptr = getattr(mv, "EmitterPtr", None)
    spectral = bool(mi.is_spectral)
    mono = bool(mi.is_monochromatic)
    polarized = bool(mi.is_polarized)
    # RGB and monochrome variants sample no wavelength (an empty array).
    wavelength_type = type(dr.zeros(mv.SurfaceInteraction3f).wavelengths)

    class EnvlightEmitter(mv.Emitter):
        """envlight's environment light as a Mitsuba emitter (see envlight.mitsuba)."""

        _is_envlight = True

        def __init__(self, props):
            super().__init__(props)
            # The scene's bounding sphere, for sample_ray: from the parameters or
            # attach_bounds(scene), since Mitsuba calls no set_scene on it.
            self.bounds = _bounds_property(props)
            self.m_d65 = mv.Texture.D65(1.0) if spectral else None
            self._warned_bystander = False
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
            _emitters.add(self)

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
                self.tables.set_texels(self.m_data.array)
            if spectral:
                # Each texel's spectrum, upsampled as envmap upsamples it: the model's
                # three coefficients and the scale, read together by the lookup
                # (constants: in spectral variants eval is not differentiable in the map).
                flat = np.ascontiguousarray(_srgb_coefficients(mi, variant, mv, rgb), np.float32).reshape(-1)
                self.spectra = self.tables.bordered_texture(mv.Float(flat) if self.tables.jit else flat, 4)

        def traverse(self, callback):
            super().traverse(callback)
            callback.put("scale", self.m_scale, mi.ParamFlags.Differentiable)
            # In spectral variants the radiance reads the model's coefficients of
            # the map, a table lookup: not differentiable in the map.
            data_flags = (mi.ParamFlags.NonDifferentiable if spectral
                          else mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous)
            callback.put("data", self.m_data, data_flags)
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
            if self.bounds is not None:
                # Beyond the scene's bounding sphere, as envmap puts it.
                centre, radius = self.bounds
                dist = 2.0 * dr.maximum(radius, dr.norm(it.p - mv.Point3f(*centre)))
            else:
                # Mitsuba does not pass the scene to a Python emitter (set_scene is
                # not called): without attach_bounds the shadow ray's end is put far
                # beyond any scene, 10⁶ times the point's distance from the origin
                # (+1); the direction of p + d·dist − p keeps f32's precision.
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
            value = self._spectrum(d, it.wavelengths, active) if spectral else self._from_rgb(rgb)
            weight = value * (self._scale() / dr.select(active, pdf, 1.0))
            return ds, self._polarize(dr.select(active, weight, 0.0))

        def sample_ray(self, time, wavelength_sample, sample2, sample3, active=True):
            """A ray leaving the environment towards the scene (light tracing): a
            direction from the light's own density (sample3), an origin uniform on
            the disc of the scene's bounding sphere facing it (sample2), wavelengths
            as ``sample_wavelengths`` draws them. Weight: radiance · π r² / pdf."""
            if self.bounds is None:
                # In JIT variants Dr.Jit traces this method for every envlight
                # emitter of the variant alive, including those of other scenes a
                # program still holds. Without bounds while another emitter of the
                # variant has them, this one is taken for such a bystander: it
                # traces rays of weight 0 and says so once. Otherwise the step was
                # forgotten, and the error raised while Mitsuba traces the
                # integrator reaches the caller of mi.render.
                others = [e for e in list(_emitters) if isinstance(e, EnvlightEmitter) and e.bounds is not None]
                if self.tables.jit and others:
                    if not self._warned_bystander:
                        self._warned_bystander = True
                        mi.Log(mi.LogLevel.Warn,
                               f'envlight emitter "{self.name}" has no scene bounds and traces no light rays; '
                               "if it belongs to the scene being rendered, call "
                               "envlight.mitsuba.attach_bounds(scene)")
                    return dr.zeros(mv.Ray3f), self._polarize(dr.zeros(mv.UnpolarizedSpectrum))
                raise RuntimeError(
                    "envlight emitter: sample_ray (light tracing, e.g. the ptracer integrator) needs the "
                    "scene's bounding sphere, which Mitsuba does not give an emitter written in Python: call "
                    "envlight.mitsuba.attach_bounds(scene) after loading the scene, or give the emitter "
                    '"bounds_center" and "bounds_radius"'
                )
            centre, radius = self.bounds
            (x, y, z), pdf, rgb, valid = self.tables.sample(sample3.x, sample3.y, self._frames())
            towards_light = mv.Vector3f(x, y, z)
            active = active & valid
            travel = -towards_light
            disc = mv.warp.square_to_uniform_disk_concentric(sample2)
            across = mv.Frame3f(travel).to_world(mv.Vector3f(disc.x, disc.y, 0.0))
            origin = mv.Point3f(*centre) + (across + towards_light) * radius
            wavelengths, value = self._emitted(towards_light, rgb, wavelength_sample, active)
            weight = value * (self._scale() * (dr.pi * radius * radius) / dr.select(active, pdf, 1.0))
            ray = mv.Ray3f(origin, travel, time, wavelengths)
            return ray, self._polarize(dr.select(active, weight, 0.0))

        def sample_wavelengths(self, si, sample, active=True):
            """Wavelengths for light arriving along ``-si.wi``, drawn as envmap draws
            them (proportional to D65 in spectral variants; none in RGB and
            monochrome ones), weighted by that light's radiance over their pdf."""
            wavelengths, value = self._emitted(-si.wi, None, sample, active)
            return wavelengths, self._polarize(dr.select(active, value * self._scale(), 0.0))

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

        # -- radiance in the variant's spectrum -----------------------------------------

        def _polarize(self, value):
            """Unpolarized emission as the variant's Spectrum."""
            return mv.depolarizer(value) if polarized else value

        def _from_rgb(self, rgb):
            """The unpolarized spectrum of an RGB radiance (scale not applied):
            itself, or its luminance in monochrome variants (as envmap's)."""
            colour = mv.Color3f(rgb[0], rgb[1], rgb[2])
            return mv.UnpolarizedSpectrum(mv.luminance(colour)) if mono else colour

        def _spectrum(self, d_world, wavelengths, active, whitepoint=True):
            """Spectral radiance (scale not applied) arriving from ``d_world`` at
            ``wavelengths``, as envmap evaluates it: the lookup's texels' model
            spectra blended with its weights, times their scales blended the same
            way, times D65 unless ``whitepoint`` is False."""
            tables = self.tables
            u, v, _ = tables.local_to_uv(*tables.to_light(*self._to_light(d_world)))
            shape, scale = None, None
            for values, weight in tables.fetch(self.spectra, u, v):
                term = mv.srgb_model_eval(mv.Vector3f(*values[:3]), wavelengths) * weight
                size = values[3] * weight
                shape = term if shape is None else shape + term
                scale = size if scale is None else scale + size
            total = shape * (scale * tables.scale)
            if whitepoint:
                si = dr.zeros(mv.SurfaceInteraction3f)
                si.wavelengths = wavelengths
                total = total * self.m_d65.eval(si, active)
            return total

        def _emitted(self, d_world, rgb, sample, active):
            """(wavelengths, radiance over their pdf, scale not applied) of light
            arriving from ``d_world``; ``rgb``, its RGB radiance, where known."""
            if not spectral:
                if rgb is None:
                    rgb = self.tables.radiance(*self._to_light(d_world))
                return dr.zeros(wavelength_type), self._from_rgb(rgb)
            n = dr.size_v(wavelength_type)
            # n shifted copies of one sample, as Mitsuba's sample_shifted makes them.
            shifted = [sample + k / n for k in range(n)]
            shifted = wavelength_type(*(dr.select(t >= 1.0, t - 1.0, t) for t in shifted))
            wavelengths, weight = self.m_d65.sample_spectrum(dr.zeros(mv.SurfaceInteraction3f), shifted, active)
            return wavelengths, weight * self._spectrum(d_world, wavelengths, active, whitepoint=False)

        def _radiance(self, d_world, wavelengths, active):
            if spectral:
                value = self._spectrum(d_world, wavelengths, active)
            else:
                value = self._from_rgb(self.tables.radiance(*self._to_light(d_world)))
            return self._polarize(dr.select(active, value * self._scale(), 0.0))

        def eval(self, si, active=True):
            return self._radiance(-si.wi, si.wavelengths, active)

        def eval_direction(self, it, ds, active=True):
            return self._radiance(ds.d, it.wavelengths, active)

        def bbox(self):
            return mv.ScalarBoundingBox3f()

        def to_string(self):
            h, w = self.m_data.shape[0], self.m_data.shape[1]
            return (f'EnvlightEmitter[filename="{self.name}", res={w}x{h}, sampling="{self.sampling}", '
                    + ", ".join(f'{k}="{v}"' for k, v in self.options.items()) + "]")

    return EnvlightEmitter
