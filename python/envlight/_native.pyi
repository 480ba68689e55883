from os import PathLike
from typing import Any, Dict, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

def release_buffers() -> int:
    """Frees the output buffers the batch calls keep for reuse; returns the bytes released."""

_F32 = npt.NDArray[np.float32]
_Sampler = Literal["inversion", "alias", "hierarchical"]
_Density = Literal["piecewise-constant", "piecewise-bilinear"]
_Mapping = Literal["equirectangular", "equal-area"]
_Lookup = Literal["bilinear", "nearest", "node"]
_Frame = Literal["z-up", "y-up"]

# The names each option accepts, in the library's order (its ALL).
SAMPLERS: Tuple[_Sampler, ...]
DENSITIES: Tuple[_Density, ...]
MAPPINGS: Tuple[_Mapping, ...]
LOOKUPS: Tuple[_Lookup, ...]
RADIANCE_FORMATS: Tuple[Literal["f32", "f16"], ...]

class EnvironmentLight:
    """An importance-sampled environment light (an HDR panorama at infinity)."""

    def __init__(
        self,
        path: Union[str, PathLike[str]],
        *,
        sampler: _Sampler = "inversion",
        density: Optional[_Density] = None,
        mapping: Optional[_Mapping] = None,
        input_mapping: _Mapping = "equirectangular",
        lookup: _Lookup = "bilinear",
        rotate: float = 0.0,
        scale: float = 1.0,
        frame: _Frame = "z-up",
        table_width: Optional[int] = None,
        equal_area_size: Optional[int] = None,
        mis_compensation: bool = False,
    ) -> None:
        """Loads a map (.hdr, .exr, .pfm, or 8-bit .png/.jpg).

        density: None (the default) takes "piecewise-bilinear" with the
        inversion sampler and no table_width, else "piecewise-constant" (the
        only density the alias and hierarchical samplers and a reduced table
        take).

        mapping: the parameterization the light samples and looks up in; None (the
        default) takes input_mapping's. A lat-long map lit with "equal-area" is
        resampled to an equal-area square.

        input_mapping: what the map is: "equirectangular" (a lat-long panorama) or
        "equal-area" (an octahedral square as PBRT-v4 writes them: it must be
        square, and is lit with the equal-area mapping only).

        equal_area_size: the side of the square a lat-long map is resampled to for
        mapping="equal-area" (at least 1); None keeps about the map's texel count.

        table_width: build the sampling table this many cells wide instead of one
        cell per texel (each cell sums a block of texels' filtered importance, so
        every lit texel keeps a positive density; radiance stays at full
        resolution). It must reduce the width and height by the same whole factor;
        piecewise-constant density only.

        mis_compensation: sample max(0, Y - mean) instead of the luminance Y (MIS
        compensation, as in PBRT-v4). The density is then 0 wherever the map is at
        or below its mean, so the light alone no longer covers the sphere: use it
        only as one technique of MIS with BSDF sampling. A map with nothing above
        its mean keeps the ordinary density.

        The accepted names are SAMPLERS, DENSITIES, MAPPINGS and LOOKUPS.

        Raises FileNotFoundError for a missing file, OSError for one that cannot be
        read or decoded, ValueError for a NaN or infinite texel (naming it), an
        unknown name or a combination of options the library refuses (naming the
        keyword), or a table width that does not fit."""
    @staticmethod
    def from_array(
        rgb: _F32,
        *,
        sampler: _Sampler = "inversion",
        density: Optional[_Density] = None,
        mapping: Optional[_Mapping] = None,
        input_mapping: _Mapping = "equirectangular",
        lookup: _Lookup = "bilinear",
        rotate: float = 0.0,
        scale: float = 1.0,
        frame: _Frame = "z-up",
        table_width: Optional[int] = None,
        equal_area_size: Optional[int] = None,
        mis_compensation: bool = False,
    ) -> "EnvironmentLight":
        """A light from an (H, W, 3) float32 array of linear RGB (row 0 at the top),
        with the options of the constructor."""
    def sample(self, u: _F32) -> Tuple[_F32, _F32, _F32]:
        """(directions (N, 3), pdf (N,), radiance (N, 3)) for u of shape (N, 2).

        A point that gives no direction (a black map) has direction 0 and pdf 0."""
    def pdf(self, directions: _F32) -> _F32:
        """Solid-angle pdf (per steradian) of each row of an (N, 3) array."""
    def radiance(self, directions: _F32) -> _F32:
        """Radiance (N, 3) arriving from each row of an (N, 3) array."""
    def invert(self, directions: _F32) -> _F32:
        """The u (N, 2) that sample() maps to each direction (not for "alias")."""
    def sample_product(
        self,
        normals: _F32,
        u: _F32,
        *,
        outgoing: Optional[_F32] = None,
        roughness: Optional[float] = None,
    ) -> Tuple[_F32, _F32, _F32]:
        """Product sampling: one direction per shading point, with density
        proportional to radiance × max(0, n·ω) (normals (N, 3), u (N, 2)); with
        outgoing (N, 3) and roughness in (0, 1], also times a GGX lobe proxy about
        the mirror direction of outgoing."""
    def pdf_product(
        self,
        normals: _F32,
        directions: _F32,
        *,
        outgoing: Optional[_F32] = None,
        roughness: Optional[float] = None,
    ) -> _F32:
        """The product sampler's pdf of each direction at its shading point."""
    def sample_portal(self, points: _F32, u: _F32, portals: npt.ArrayLike) -> Tuple[_F32, _F32, _F32]:
        """Portal sampling: one direction per point (points (N, 3), u (N, 2)) through
        the portals only (portals (K, 4, 3): K ≤ 8 planar convex quads, corners in
        order around each, either winding), with density proportional to radiance
        restricted to them; (directions (N, 3), pdf (N,), radiance (N, 3)), a zero
        direction with pdf 0 where no lit sky is seen through a portal. The portal
        tables are built once and reused while the same portals are passed.
        Raises ValueError for a bad shape or a degenerate, non-planar or non-convex
        quad."""
    def pdf_portal(self, points: _F32, directions: _F32, portals: npt.ArrayLike) -> _F32:
        """The portal light's solid-angle pdf (sr⁻¹) of each direction from its point:
        the exact mixture over the portals the ray crosses, 0 through no portal."""
    def verify(
        self, *, samples: int = 200000, seed: int = 0, normal: Optional[Sequence[float]] = None
    ) -> list[dict]:
        """The invariant checks (normalisation, pdf consistency, invert, chi-square,
        unbiasedness, support, efficiency) as a list of dicts with keys check, value,
        threshold, samples, result ("pass", "FAIL", "info", "skip")."""
    def gpu_tables(
        self, radiance: Literal["f32", "f16"] = "f32"
    ) -> Dict[str, Union[npt.NDArray[Any], int]]:
        """The light's flat GPU tables (docs/gpu-tables.md, layout version 1) as
        numpy arrays, one entry per section present, by name:

        - "params": uint32 (64,), the parameter block (params[24] is the version);
        - "marginal_cdf": uint32 (table_height + 1,); "marginal_guide": uint32 (G,);
          "conditional_cdf": uint32 (table_height, table_width + 1);
          "conditional_guide": uint32 (table_height, 2**bits) (inversion sampler);
        - "alias_slots": uint32 (n, 2), threshold float32 bits and alias cell;
          "alias_func": float32 (table_height, table_width) (alias sampler);
        - "bilinear_values": float32 (H + 2, W + 2) (piecewise-bilinear density);
        - "radiance": float32 (H, W, 3), or float16 (H, W, 4) with alpha 0 for
          radiance="f16"; unscaled (the scale is a parameter);

        plus "tables", the uint32 tables buffer a shader binds (sections 2-8 in id
        order, each padded to 16 bytes; params[49] words), and "version" (1).

        Raises ValueError for the hierarchical sampler (not ported to the GPU), or
        radiance="f16" with a texel above 65504."""
    def product_tables(self) -> Dict[str, Any]:
        """The cosine product sampler's tables (docs/gpu-tables.md, "Product
        tables") as numpy arrays, for a port of sample_product / pdf_product without
        `outgoing` (envlight.mitsuba's sampling="product"): "density", "image"
        (w, h), "cells" (cw, ch), "patches" (pw, ph), "grid"; uint32 "col_patch",
        "row_patch", "cell_widths" (ch, cw), "cell_slots" (cw ch, 2), "spans"
        (pw ph, 5), "table_slots" (nodes pw ph, 2), "table_widths" (pw ph, nodes);
        "node_empty" uint8, "node_totals" float64 (nodes,); "bright" float64
        (B, 20), "bright_of_patch" uint8 (pw ph,); "bound_share", "box_slack",
        "horizon_band", "min_horizon_band" (a point's band: draws this close below
        the horizon are reflected above it);
        and for the piecewise-bilinear density "node_values" float32 (h + 2, w + 2),
        "u_nodes", "v_nodes" float64. Directions in the light's z-up frame before
        its rotation."""
    def sun(self) -> Optional[Dict[str, Any]]:
        """The map's sun (its brightest compact source, as a uniform disc), or None
        when it has none (radius > 5°, contrast < 20 or < 1% of the power).

        Keys: "direction" (unit 3-tuple in this light's frame, rotation applied),
        "angular_radius_deg", "solid_angle_sr", "radiance" and "irradiance" (RGB
        3-tuples, scale applied; irradiance at normal incidence, L π sin² r),
        "power_fraction" (share of ∫Y dω), "elevation_deg" and "azimuth_deg" (of
        the z-up direction: above the xy plane, from +x towards +y), "contrast"
        (the disc's luminance over the surrounding sky's median)."""
    def sun_residual(self) -> _F32:
        """The light's image without its sun: (H, W, 3) float32, same size and
        mapping, the sun's texels in-painted from the sky around it, unscaled; the
        image itself when there is no sun. Residual + the disc of sun() reproduce
        the map's irradiance at any normal that does not graze the sun."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def integral_rgb(self) -> Tuple[float, float, float]: ...
    @property
    def integral_luminance(self) -> float: ...
    @property
    def efficiency(self) -> float: ...
    @property
    def brightest_direction(self) -> Tuple[float, float, float]: ...
    @property
    def table_size(self) -> Tuple[int, int]:
        """(width, height) of the sampling table in cells."""
    @property
    def full_table_efficiency(self) -> Optional[float]:
        """With table_width: the full-resolution table's efficiency (else None)."""
    @property
    def sampling_bytes(self) -> int: ...
    @property
    def frame(self) -> _Frame: ...

class VisibilityCache:
    """Sampling of radiance × max(0, n·ω) in proportion to what each region of a
    scene sees of the sky, learned through the caller's ray tracer, with an exact
    pdf that is positive wherever the unoccluded integrand is (the design notes, §10).

    ``trace(origins, directions)`` receives ``(M, 3)`` float32 arrays in the
    light's frame (rays start exactly at the given points: offset them as your
    shadow rays need) and returns an ``(M,)`` float32 array of transmittance in
    [0, 1] (1: the ray escapes). Its exceptions reach the caller unchanged; a wrong
    shape, NaN or a value outside [0, 1] is a ``ValueError``.
    """

    def __init__(
        self,
        light: EnvironmentLight,
        points: _F32,
        normals: _F32,
        trace: Any,
        *,
        radius: Optional[float] = None,
        normal_bins: Optional[int] = None,
        target_entries: Optional[int] = None,
        memory_budget: Optional[int] = None,
        rays_per_patch: Optional[int] = None,
        refine_rays: Optional[int] = None,
        learned_share: Optional[float] = None,
        prior: Optional[float] = None,
        seed: Optional[int] = None,
    ) -> None: ...
    def sample(self, points: _F32, normals: _F32, u: _F32) -> Tuple[_F32, _F32, _F32]:
        """``(directions (N, 3), pdf (N,), radiance (N, 3))`` at each shading point."""
    def pdf(self, points: _F32, normals: _F32, directions: _F32) -> _F32:
        """The density (per steradian) of ``sample`` for each point and direction."""
    def save(self, path: Union[str, PathLike[str]], scene_key: str) -> None:
        """Writes the cache with the key of the scene it was learned in."""
    @staticmethod
    def load(
        path: Union[str, PathLike[str]], light: EnvironmentLight, scene_key: str
    ) -> "VisibilityCache":
        """Reads a saved cache; ``ValueError`` naming both keys for another light or scene."""
    def summary(self) -> Dict[str, Any]:
        """``entries``, ``bytes``, ``radius``, ``mean_visibility``, ``rays``."""
