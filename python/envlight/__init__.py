"""Image-based environment lighting with exact importance sampling.

``EnvironmentLight`` loads an HDR panorama (``.hdr``, ``.exr``, ``.pfm``) or takes an
``(H, W, 3)`` float32 array, builds a sampling distribution whose density follows
the map's luminance, and answers in batches over numpy arrays (float32):

- ``sample(u)``: ``u`` of shape ``(N, 2)`` in ``[0, 1)`` gives ``(directions (N, 3),
  pdf (N,), radiance (N, 3))``, the pdf per steradian;
- ``pdf(directions)``, ``radiance(directions)``, ``invert(directions)``;
- ``sample_product(normals, u)`` and ``pdf_product(normals, directions)``: product
  sampling at shading points, in proportion to radiance × max(0, n·ω);
- ``verify()``: the invariant checks, as ``envlight verify`` prints them.

``VisibilityCache(light, points, normals, trace)`` learns, through ``trace``, your
ray tracer, where each region of a scene sees the sky, and samples radiance ×
max(0, n·ω) there with an exact pdf (``sample``, ``pdf``, ``save``, ``load``).

Large batch outputs (256 KiB and up) live in buffers that go back to a small
cache when their arrays are freed, so that the next batch call does not pay for
fresh pages (at most 8 buffers, 512 MiB); ``release_buffers()`` empties it.

The light's options are keywords of the constructors (``help(EnvironmentLight)``);
``SAMPLERS``, ``DENSITIES``, ``MAPPINGS``, ``LOOKUPS`` and ``RADIANCE_FORMATS`` are
the names each accepts, as the library spells them.

``envlight.mitsuba.register()`` adds the light to Mitsuba 3 as the emitter type
``"envlight"`` (see ``help(envlight.mitsuba)``).

Frames (``frame=``): ``"z-up"`` is the library's (a map point ``(u, v)`` looks
along ``(sin θ cos φ, sin θ sin φ, cos θ)`` with ``θ = π v``, ``φ = 2π u``);
``"y-up"`` is Mitsuba 3's envmap frame, ``(y, z, -x)`` of the z-up direction. The
pdf per steradian is the same number in both.

====================  ===============  ===============
map point             z-up             y-up
====================  ===============  ===============
top row (v = 0)       (0, 0, 1)        (0, 1, 0)
centre (0.5, 0.5)     (-1, 0, 0)       (0, 0, 1)
u = 0.25, v = 0.5     (0, 1, 0)        (1, 0, 0)
u = 0, v = 0.5        (1, 0, 0)        (0, 0, -1)
====================  ===============  ===============
"""

from ._native import (
    DENSITIES,
    LOOKUPS,
    MAPPINGS,
    RADIANCE_FORMATS,
    SAMPLERS,
    EnvironmentLight,
    VisibilityCache,
    __version__,
    release_buffers,
)

__all__ = [
    "DENSITIES",
    "EnvironmentLight",
    "LOOKUPS",
    "MAPPINGS",
    "RADIANCE_FORMATS",
    "SAMPLERS",
    "VisibilityCache",
    "__version__",
    "release_buffers",
]
