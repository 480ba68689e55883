//! `envlight.VisibilityCache`: the library's visibility cache (docs/design.md §10)
//! over numpy arrays, learning through a Python callable that traces rays.

use crate::{directions, rows, same_length, to_py_err, Frame, PyEnvironmentLight};
use envlight::visibility::{VisibilityError, VisibilityOptions};
use envlight::{Factor, Vec3, VisibilityCache};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;
use std::path::PathBuf;

/// A visibility cache over a light, built from shading points and a tracer.
#[pyclass(frozen, module = "envlight._native", name = "VisibilityCache")]
pub(crate) struct PyVisibilityCache {
    cache: VisibilityCache,
    frame: Frame,
}

/// `(N, 3)` positions and normals in `frame`, as z-up vectors, checked for the
/// same length.
fn points_and_normals(
    points: &PyReadonlyArray2<'_, f32>,
    normals: &PyReadonlyArray2<'_, f32>,
    frame: Frame,
) -> PyResult<(Vec<Vec3>, Vec<Vec3>)> {
    let points = rows::<3>(points, "points")?;
    let normals = rows::<3>(normals, "normals")?;
    let (points, normals) = (directions(&points, frame), directions(&normals, frame));
    same_length("points", points.len(), "normals", normals.len())?;
    Ok((points.into_owned(), normals.into_owned()))
}

/// `vectors` (z-up) as an `(N, 3)` float32 array in `frame`.
fn array3<'py>(
    py: Python<'py>,
    vectors: &[Vec3],
    frame: Frame,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let flat: Vec<f32> = vectors
        .iter()
        .flat_map(|&v| frame.z_up_to_frame(v).to_array())
        .collect();
    PyArray1::from_vec(py, flat).reshape([vectors.len(), 3])
}

/// The Python exception for a failed build: the callable's own exception
/// unchanged, a `ValueError` for everything else.
fn build_error(e: VisibilityError<PyErr>) -> PyErr {
    match e {
        VisibilityError::Trace(e) => e,
        other => PyValueError::new_err(other.to_string()),
    }
}

impl PyVisibilityCache {
    /// The shading points (z-up) and a `(N, K)` array of one row per point, as
    /// given (`what` names it in errors).
    #[allow(clippy::type_complexity)]
    fn at_points<const K: usize>(
        &self,
        points: &PyReadonlyArray2<'_, f32>,
        normals: &PyReadonlyArray2<'_, f32>,
        values: &PyReadonlyArray2<'_, f32>,
        what: &str,
    ) -> PyResult<(Vec<Vec3>, Vec<Vec3>, Vec<f32>)> {
        let (points, normals) = points_and_normals(points, normals, self.frame)?;
        let values = rows::<K>(values, what)?;
        same_length("points", points.len(), what, values.len() / K)?;
        Ok((points, normals, values.into_owned()))
    }
}

#[pymethods]
impl PyVisibilityCache {
    /// Builds the cache of `light` from `points` and `normals` (`(N, 3)` float32
    /// in the light's frame), calling `trace(origins, directions)` with `(M, 3)`
    /// float32 arrays (rays start exactly at the given points: offset them as
    /// your shadow rays need) for an `(M,)` array of transmittance in [0, 1].
    /// Options as the library's `VisibilityOptions`; omitted ones take its
    /// defaults.
    #[new]
    #[pyo3(signature = (light, points, normals, trace, *, radius=None, normal_bins=None, target_entries=None, memory_budget=None, rays_per_patch=None, refine_rays=None, learned_share=None, prior=None, seed=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        light: &Bound<'_, PyEnvironmentLight>,
        points: PyReadonlyArray2<'_, f32>,
        normals: PyReadonlyArray2<'_, f32>,
        trace: Bound<'_, PyAny>,
        radius: Option<f32>,
        normal_bins: Option<usize>,
        target_entries: Option<usize>,
        memory_budget: Option<usize>,
        rays_per_patch: Option<usize>,
        refine_rays: Option<usize>,
        learned_share: Option<f32>,
        prior: Option<f32>,
        seed: Option<u64>,
    ) -> PyResult<Self> {
        let light = light.get();
        let frame = light.frame;
        let d = VisibilityOptions::default();
        let options = VisibilityOptions {
            radius: radius.or(d.radius),
            normal_bins: normal_bins.unwrap_or(d.normal_bins),
            target_entries: target_entries.unwrap_or(d.target_entries),
            memory_budget: memory_budget.unwrap_or(d.memory_budget),
            rays_per_patch: rays_per_patch.unwrap_or(d.rays_per_patch),
            refine_rays: refine_rays.unwrap_or(d.refine_rays),
            learned_share: learned_share.unwrap_or(d.learned_share),
            prior: prior.unwrap_or(d.prior),
            seed: seed.unwrap_or(d.seed),
        };
        let (points, normals) = points_and_normals(&points, &normals, frame)?;
        let numpy = py.import("numpy")?;
        let call = |origins: &[Vec3], directions: &[Vec3], out: &mut [f32]| -> PyResult<()> {
            let result =
                trace.call1((array3(py, origins, frame)?, array3(py, directions, frame)?))?;
            let shape_error = || {
                PyValueError::new_err(format!(
                    "trace must return an array of shape ({},) of numbers, not {}",
                    out.len(),
                    result.repr().map_or_else(|_| "?".into(), |r| r.to_string())
                ))
            };
            // Any numeric array (bool, float64) is taken as float32.
            let t: PyReadonlyArray1<'_, f32> = numpy
                .call_method1("asarray", (&result, "float32"))
                .and_then(|a| a.extract())
                .map_err(|_| shape_error())?;
            let t = t.as_array();
            if t.len() != out.len() {
                return Err(PyValueError::new_err(format!(
                    "trace returned {} transmittances for {} rays",
                    t.len(),
                    out.len()
                )));
            }
            for (i, (&v, o)) in t.iter().zip(out.iter_mut()).enumerate() {
                if !(0.0..=1.0).contains(&v) {
                    return Err(PyValueError::new_err(format!(
                        "trace returned transmittance {v} for ray {i}: it must be in [0, 1]"
                    )));
                }
                *o = v;
            }
            Ok(())
        };
        let cache =
            VisibilityCache::build(light.product().clone(), &points, &normals, &options, call)
                .map_err(build_error)?;
        Ok(Self { cache, frame })
    }

    /// `(directions (N, 3), pdf (N,), radiance (N, 3))`: one direction per shading
    /// point `(points[i], normals[i])` for `u[i]` in [0, 1)², from the cache's
    /// mixture, pdf per steradian; a point where nothing can be sampled gives a
    /// zero direction with pdf 0.
    fn sample<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        normals: PyReadonlyArray2<'py, f32>,
        u: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<crate::Samples<'py>> {
        let (points, normals, u) = self.at_points::<2>(&points, &normals, &u, "u")?;
        let samples: Vec<Option<envlight::LightSample>> = py.detach(|| {
            (0..points.len())
                .into_par_iter()
                .map(|i| {
                    let point = self.cache.at(points[i], &Factor::cosine(normals[i]));
                    point.sample([u[2 * i], u[2 * i + 1]])
                })
                .collect()
        });
        let directions: Vec<Vec3> = samples
            .iter()
            .map(|s| s.map_or(Vec3::default(), |s| s.direction))
            .collect();
        let pdf: Vec<f32> = samples.iter().map(|s| s.map_or(0.0, |s| s.pdf)).collect();
        let radiance: Vec<f32> = samples
            .iter()
            .flat_map(|s| s.map_or([0.0; 3], |s| s.radiance))
            .collect();
        Ok((
            array3(py, &directions, self.frame)?,
            PyArray1::from_vec(py, pdf),
            PyArray1::from_vec(py, radiance).reshape([points.len(), 3])?,
        ))
    }

    /// The density (per steradian) of `sample` at each `(points[i], normals[i])`
    /// for `directions[i]` (unit, `(N, 3)` float32).
    fn pdf<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f32>,
        normals: PyReadonlyArray2<'py, f32>,
        directions: PyReadonlyArray2<'py, f32>,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        let (points, normals, dirs) =
            self.at_points::<3>(&points, &normals, &directions, "directions")?;
        let dirs = crate::directions(&dirs, self.frame);
        let pdf: Vec<f32> = py.detach(|| {
            (0..points.len())
                .into_par_iter()
                .map(|i| {
                    self.cache
                        .at(points[i], &Factor::cosine(normals[i]))
                        .pdf(dirs[i])
                })
                .collect()
        });
        Ok(PyArray1::from_vec(py, pdf))
    }

    /// Writes the cache to `path` with `scene_key`, a string saying which scene it
    /// was learned in; `VisibilityCache.load` refuses another key or light.
    fn save(&self, py: Python<'_>, path: PathBuf, scene_key: &str) -> PyResult<()> {
        py.detach(|| self.cache.save(&path, scene_key))
            .map_err(to_py_err)
    }

    /// Reads a cache saved by `save` for `light` in the scene `scene_key`
    /// (`ValueError` naming both keys when it was made for another light or
    /// scene; `OSError` for a damaged file).
    #[staticmethod]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        light: &Bound<'_, PyEnvironmentLight>,
        scene_key: &str,
    ) -> PyResult<Self> {
        let light = light.get();
        let product = light.product().clone();
        let cache = py
            .detach(|| VisibilityCache::load(&path, product, scene_key))
            .map_err(to_py_err)?;
        Ok(Self {
            cache,
            frame: light.frame,
        })
    }

    /// What the cache holds: `entries`, `bytes`, `radius`, `mean_visibility`,
    /// `rays`.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.cache.summary();
        let d = PyDict::new(py);
        d.set_item("entries", s.entries)?;
        d.set_item("bytes", s.bytes)?;
        d.set_item("radius", s.radius)?;
        d.set_item("mean_visibility", s.mean_visibility)?;
        d.set_item("rays", s.rays)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let s = self.cache.summary();
        format!(
            "VisibilityCache(entries={}, bytes={}, mean_visibility={:.3})",
            s.entries, s.bytes, s.mean_visibility
        )
    }
}
