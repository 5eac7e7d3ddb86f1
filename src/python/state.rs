//! Saved states of fitted surfaces: a [`Fitted`] as a dict of numpy arrays and numbers, and
//! back, through the core's parts ([`SurfaceParts`], [`PartitionParts`]). Pickling and
//! `implicitmesh.save`/`load` use it.

use super::convert::{points, points_to_py, values, values_to_py};
use super::errors::value_error;
use crate::field::rbf::constraints::Constraints;
use crate::field::rbf::kernel::Kernel;
use crate::field::rbf::partition::octree::Node;
use crate::field::rbf::partition::{
    PartitionParts, PartitionSettings, PartitionSurface, PatchParts,
};
use crate::field::rbf::Fitted;
use crate::field::rbf::{FitSettings, SurfaceParts, VariationalSurface};
use crate::field::scan::surface::guard_of;
use crate::field::scan::{ScanReport, ScanSettings, ScanSurface};
use glam::DVec3;
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// The version of the layout below; states of other versions are refused. Format 1 differs
/// only in a partition fit's patches: each kept its normalised centres, where format 2 keeps
/// indices into the constraints (`patch_index`) for the patches marked in `patch_shared`.
/// Format 3 adds `constraint_normal_of`, the data points that have a normal constraint (in
/// formats 1 and 2 every data point with an offset has one).
const FORMAT: i64 = 3;

fn bad(what: impl std::fmt::Display) -> PyErr {
    value_error("state", format!("not a saved surface: {what}"))
}

fn item<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?.ok_or_else(|| bad(format!("no {key:?}")))
}

fn number<T: for<'a, 'py> FromPyObject<'a, 'py>>(d: &Bound<'_, PyDict>, key: &str) -> PyResult<T> {
    item(d, key)?
        .extract()
        .map_err(|_| bad(format!("{key:?} is not a number of the right kind")))
}

fn points_of(d: &Bound<'_, PyDict>, key: &'static str) -> PyResult<Vec<DVec3>> {
    points(&item(d, key)?, key)
}

fn values_of(d: &Bound<'_, PyDict>, key: &'static str) -> PyResult<Vec<f64>> {
    values(&item(d, key)?, key)
}

fn counts_of(d: &Bound<'_, PyDict>, key: &'static str) -> PyResult<Vec<usize>> {
    let v: Vec<i64> = item(d, key)?
        .extract()
        .map_err(|_| bad(format!("{key:?} is not a list of integers")))?;
    v.into_iter()
        .map(|x| usize::try_from(x).map_err(|_| bad(format!("{key:?} holds {x}"))))
        .collect()
}

fn four(v: Vec<f64>, key: &str) -> PyResult<[f64; 4]> {
    v.try_into()
        .map_err(|_| bad(format!("{key:?} needs 4 numbers")))
}

fn counts_to_py(py: Python<'_>, v: impl IntoIterator<Item = usize>) -> Bound<'_, PyAny> {
    PyArray1::from_vec(py, v.into_iter().map(|x| x as i64).collect()).into_any()
}

fn put_constraints(py: Python<'_>, d: &Bound<'_, PyDict>, c: &Constraints) -> PyResult<()> {
    d.set_item("constraint_points", points_to_py(py, c.points.clone())?)?;
    d.set_item("constraint_values", values_to_py(py, c.values.clone()))?;
    d.set_item("constraint_offsets", values_to_py(py, c.offsets.clone()))?;
    d.set_item("constraint_boundary", c.boundary)?;
    let normal_of: Vec<usize> = c.normal_of.iter().map(|&j| j as usize).collect();
    d.set_item("constraint_normal_of", counts_to_py(py, normal_of))?;
    d.set_item("merged_points", c.merged)
}

fn constraints_of(d: &Bound<'_, PyDict>) -> PyResult<Constraints> {
    let points = points_of(d, "constraint_points")?;
    let offsets = values_of(d, "constraint_offsets")?;
    let boundary: usize = number(d, "constraint_boundary")?;
    // Formats 1 and 2 placed a normal constraint for every data point that has an offset.
    let normal_of: Vec<u32> = match d.get_item("constraint_normal_of")? {
        Some(_) => counts_of(d, "constraint_normal_of")?
            .into_iter()
            .map(|j| u32::try_from(j).map_err(|_| bad(format!("normal of data point {j}"))))
            .collect::<PyResult<_>>()?,
        None if offsets.len() == boundary && points.len() >= 2 * boundary => {
            (0..boundary as u32).collect()
        }
        None => vec![],
    };
    let increasing = normal_of.windows(2).all(|w| w[0] < w[1]);
    if !increasing
        || normal_of.last().is_some_and(|&j| j as usize >= boundary)
        || boundary + normal_of.len() > points.len()
    {
        return Err(bad(
            "\"constraint_normal_of\" does not name data points in order",
        ));
    }
    Ok(Constraints {
        points,
        values: values_of(d, "constraint_values")?,
        offsets,
        boundary,
        normal_of,
        merged: match d.get_item("merged_points")? {
            Some(_) => number(d, "merged_points")?,
            None => 0,
        },
    })
}

/// The state of a fitted surface: its fit's, and for a scan fit its cleaned points, their
/// normals and areas, the bands and the report under keys `scan_*`.
pub fn state<'py>(py: Python<'py>, fitted: &Fitted) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("format", FORMAT)?;
    let Some(scan) = fitted.scan() else {
        put_fit(py, &d, fitted)?;
        return Ok(d);
    };
    put_fit(py, &d, scan.surface.fit())?;
    let guard = scan.surface.guard();
    let r = &scan.report;
    let (near, far) = guard.bands();
    d.set_item("scan_points", points_to_py(py, guard.points().to_vec())?)?;
    d.set_item("scan_normals", points_to_py(py, guard.normals().to_vec())?)?;
    d.set_item("scan_areas", values_to_py(py, guard.areas().to_vec()))?;
    d.set_item("scan_spacing", r.spacing)?;
    d.set_item("scan_near", near / r.spacing)?;
    d.set_item("scan_far", far / r.spacing)?;
    d.set_item("scan_outliers", PyArray1::from_vec(py, r.outliers.clone()))?;
    d.set_item("scan_given_points", r.points)?;
    d.set_item("scan_noise", r.noise)?;
    d.set_item("scan_normals_corrected", r.normals_corrected)?;
    d.set_item("scan_turned_outward", r.turned_outward)?;
    d.set_item("scan_normals_estimated", r.normals_estimated)?;
    d.set_item(
        "scan_distances",
        values_to_py(py, vec![r.distance_mean, r.distance_p99, r.distance_max]),
    )?;
    Ok(d)
}

/// A global or partition fit's entries into `d`.
fn put_fit(py: Python<'_>, d: &Bound<'_, PyDict>, fitted: &Fitted) -> PyResult<()> {
    match fitted {
        Fitted::Scan(s) => put_fit(py, d, s.surface.fit())?,
        Fitted::Global(s) => {
            let p = py.detach(|| s.parts());
            d.set_item("method", "global")?;
            put_constraints(py, d, &p.constraints)?;
            d.set_item("kernel", p.kernel.name())?;
            d.set_item("centers", points_to_py(py, p.centers)?)?;
            d.set_item("weights", values_to_py(py, p.weights))?;
            d.set_item("polynomial", values_to_py(py, p.polynomial.to_vec()))?;
            d.set_item("shift", values_to_py(py, p.shift.to_array().to_vec()))?;
            d.set_item("scale", p.scale)?;
            d.set_item(
                "normalized_centers",
                points_to_py(py, p.normalized_centers)?,
            )?;
            d.set_item("normalized_weights", values_to_py(py, p.normalized_weights))?;
            let np = p.normalized_polynomial.to_vec();
            d.set_item("normalized_polynomial", values_to_py(py, np))?;
            d.set_item("residual", p.residual)?;
            d.set_item("factorization", p.factorization)?;
        }
        Fitted::Partition(s) => {
            let (p, flat) = py.detach(|| {
                let mut p = s.parts();
                let flat = FlatPatches::of(&std::mem::take(&mut p.patches));
                (p, flat)
            });
            d.set_item("method", "partition")?;
            put_constraints(py, d, &p.constraints)?;
            let st = &p.settings;
            d.set_item("kernel", st.fit.kernel.name())?;
            d.set_item("smoothing", st.fit.smoothing)?;
            d.set_item("memory_limit", st.fit.memory_limit)?;
            d.set_item("max_per_leaf", st.max_per_leaf)?;
            d.set_item("overlap", st.overlap)?;
            d.set_item("max_patch", st.max_patch)?;
            d.set_item("min_points", st.min_points)?;
            d.set_item("residual", p.residual)?;
            flat.put(py, d)?;
            if let Some(nodes) = &p.tree {
                put_tree(py, d, nodes)?;
            }
        }
    }
    Ok(())
}

/// A cut's octree: per node its cube's centre and half side, and its first child (0 for a
/// leaf).
fn put_tree(py: Python<'_>, d: &Bound<'_, PyDict>, nodes: &[Node]) -> PyResult<()> {
    d.set_item(
        "tree_centre",
        points_to_py(py, nodes.iter().map(|n| n.centre).collect())?,
    )?;
    d.set_item(
        "tree_half",
        values_to_py(py, nodes.iter().map(|n| n.half).collect()),
    )?;
    d.set_item(
        "tree_children",
        counts_to_py(py, nodes.iter().map(|n| n.children as usize)),
    )
}

/// The octree [`put_tree`] stored, if any.
fn tree_of(d: &Bound<'_, PyDict>) -> PyResult<Option<Vec<Node>>> {
    if d.get_item("tree_centre")?.is_none() {
        return Ok(None);
    }
    let (centre, half) = (points_of(d, "tree_centre")?, values_of(d, "tree_half")?);
    let children = counts_of(d, "tree_children")?;
    if half.len() != centre.len() || children.len() != centre.len() {
        return Err(bad("the octree's arrays differ in length"));
    }
    centre
        .into_iter()
        .zip(half)
        .zip(children)
        .map(|((centre, half), children)| {
            Ok(Node {
                centre,
                half,
                children: u32::try_from(children)
                    .map_err(|_| bad("\"tree_children\" holds a number over 2³²"))?,
                start: 0,
                end: 0,
            })
        })
        .collect::<PyResult<_>>()
        .map(Some)
}

/// The patches, flattened: per patch its ball, counts and fit's numbers; their weights one
/// after another (`patch_start` says where each patch's begin), and so their centres: indices
/// into the constraints (`patch_index`, uint32) for the patches `patch_shared` marks, normalised
/// centres of their own (`patch_normalized_centers`) for the others. Made and read without
/// the GIL; only the conversions to and from numpy hold it.
struct FlatPatches {
    start: Vec<usize>,
    centre: Vec<DVec3>,
    radius: Vec<f64>,
    inside: Vec<usize>,
    size: Vec<usize>,
    normalized_centers: Vec<DVec3>,
    shared: Vec<usize>,
    index: Vec<u32>,
    normalized_weights: Vec<f64>,
    normalized_polynomial: Vec<f64>,
    polynomial: Vec<f64>,
    shift: Vec<f64>,
    scale: Vec<f64>,
    residual: Vec<f64>,
    cholesky: Vec<usize>,
}

impl FlatPatches {
    fn of(patches: &[PatchParts]) -> Self {
        let fits = || patches.iter().map(|q| &q.fit);
        let flat = |f: &dyn Fn(&SurfaceParts) -> Vec<f64>| fits().flat_map(f).collect::<Vec<f64>>();
        let mut start = vec![0usize];
        for f in fits() {
            start.push(start.last().unwrap() + f.normalized_weights.len());
        }
        FlatPatches {
            start,
            centre: patches.iter().map(|q| q.centre).collect(),
            radius: patches.iter().map(|q| q.radius).collect(),
            inside: patches.iter().map(|q| q.inside).collect(),
            size: patches.iter().map(|q| q.size).collect(),
            normalized_centers: fits()
                .flat_map(|f| f.normalized_centers.iter().copied())
                .collect(),
            shared: patches
                .iter()
                .map(|q| !q.index.is_empty() as usize)
                .collect(),
            index: patches
                .iter()
                .flat_map(|q| q.index.iter().copied())
                .collect(),
            normalized_weights: fits()
                .flat_map(|f| f.normalized_weights.iter().copied())
                .collect(),
            normalized_polynomial: flat(&|f| f.normalized_polynomial.to_vec()),
            polynomial: flat(&|f| f.polynomial.to_vec()),
            shift: flat(&|f| f.shift.to_array().to_vec()),
            scale: fits().map(|f| f.scale).collect(),
            residual: fits().map(|f| f.residual).collect(),
            cholesky: fits()
                .map(|f| (f.factorization == "cholesky") as usize)
                .collect(),
        }
    }

    fn put(self, py: Python<'_>, d: &Bound<'_, PyDict>) -> PyResult<()> {
        d.set_item("patch_start", counts_to_py(py, self.start))?;
        d.set_item("patch_centre", points_to_py(py, self.centre)?)?;
        d.set_item("patch_radius", values_to_py(py, self.radius))?;
        d.set_item("patch_inside", counts_to_py(py, self.inside))?;
        d.set_item("patch_size", counts_to_py(py, self.size))?;
        let nc = points_to_py(py, self.normalized_centers)?;
        d.set_item("patch_normalized_centers", nc)?;
        d.set_item("patch_shared", counts_to_py(py, self.shared))?;
        d.set_item("patch_index", PyArray1::from_vec(py, self.index))?;
        let nw = values_to_py(py, self.normalized_weights);
        d.set_item("patch_normalized_weights", nw)?;
        let np = values_to_py(py, self.normalized_polynomial);
        d.set_item("patch_normalized_polynomial", np)?;
        d.set_item("patch_polynomial", values_to_py(py, self.polynomial))?;
        d.set_item("patch_shift", values_to_py(py, self.shift))?;
        d.set_item("patch_scale", values_to_py(py, self.scale))?;
        d.set_item("patch_residual", values_to_py(py, self.residual))?;
        d.set_item("patch_cholesky", counts_to_py(py, self.cholesky))
    }

    fn read(d: &Bound<'_, PyDict>) -> PyResult<Self> {
        let centre = points_of(d, "patch_centre")?;
        let n = centre.len();
        // Format 1: every patch has centres of its own.
        let (shared, index) = match d.get_item("patch_index")? {
            Some(index) => (counts_of(d, "patch_shared")?, indices(&index)?),
            None => (vec![0; n], vec![]),
        };
        Ok(FlatPatches {
            start: counts_of(d, "patch_start")?,
            centre,
            radius: values_of(d, "patch_radius")?,
            inside: counts_of(d, "patch_inside")?,
            size: counts_of(d, "patch_size")?,
            normalized_centers: points_of(d, "patch_normalized_centers")?,
            shared,
            index,
            normalized_weights: values_of(d, "patch_normalized_weights")?,
            normalized_polynomial: values_of(d, "patch_normalized_polynomial")?,
            polynomial: values_of(d, "patch_polynomial")?,
            shift: values_of(d, "patch_shift")?,
            scale: values_of(d, "patch_scale")?,
            residual: values_of(d, "patch_residual")?,
            cholesky: counts_of(d, "patch_cholesky")?,
        })
    }

    /// The patches, when the arrays' lengths agree.
    fn patches(self, kernel: Kernel) -> PyResult<Vec<PatchParts>> {
        let f = self;
        let n = f.centre.len();
        let lengths_agree = f.start.len() == n + 1
            && [
                f.radius.len(),
                f.inside.len(),
                f.size.len(),
                f.scale.len(),
                f.residual.len(),
            ]
            .iter()
            .chain(&[f.cholesky.len(), f.shared.len()])
            .all(|&l| l == n)
            && f.normalized_polynomial.len() == 4 * n
            && f.polynomial.len() == 4 * n
            && f.shift.len() == 3 * n
            && f.start.windows(2).all(|w| w[0] <= w[1])
            && f.start[0] == 0
            && f.start[n] == f.normalized_weights.len()
            && (0..n).all(|k| f.shared[k] <= 1);
        if !lengths_agree {
            return Err(bad("the patches' arrays differ in length"));
        }
        // The runs of centres of each patch: in `index` when shared, else in the normalised
        // centres.
        let (mut own_at, mut index_at) = (0, 0);
        let mut runs = Vec::with_capacity(n);
        for k in 0..n {
            let len = f.start[k + 1] - f.start[k];
            let at = if f.shared[k] == 1 {
                &mut index_at
            } else {
                &mut own_at
            };
            runs.push(*at..*at + len);
            *at += len;
        }
        if !(own_at == f.normalized_centers.len() && index_at == f.index.len()) {
            return Err(bad("the patches' arrays differ in length"));
        }
        let four_at = |v: &[f64], k: usize| -> [f64; 4] { v[4 * k..4 * k + 4].try_into().unwrap() };
        Ok((0..n)
            .map(|k| {
                let (weights, centres) = (f.start[k]..f.start[k + 1], runs[k].clone());
                let own = f.shared[k] == 0;
                PatchParts {
                    centre: f.centre[k],
                    radius: f.radius[k],
                    inside: f.inside[k],
                    size: f.size[k],
                    fit: SurfaceParts {
                        kernel,
                        polynomial: four_at(&f.polynomial, k),
                        shift: DVec3::from_slice(&f.shift[3 * k..3 * k + 3]),
                        scale: f.scale[k],
                        normalized_centers: if own {
                            f.normalized_centers[centres.clone()].to_vec()
                        } else {
                            vec![]
                        },
                        normalized_weights: f.normalized_weights[weights].to_vec(),
                        normalized_polynomial: four_at(&f.normalized_polynomial, k),
                        residual: f.residual[k],
                        factorization: if f.cholesky[k] == 1 {
                            "cholesky"
                        } else {
                            "lblt"
                        }
                        .into(),
                        ..Default::default()
                    },
                    index: if own {
                        vec![]
                    } else {
                        f.index[centres].to_vec()
                    },
                }
            })
            .collect())
    }
}

/// A uint32 array's numbers.
fn indices(a: &Bound<'_, PyAny>) -> PyResult<Vec<u32>> {
    indices_named(a, "patch_index")
}

/// The numbers of the uint32 array `a`, the state's entry `key`.
fn indices_named(a: &Bound<'_, PyAny>, key: &str) -> PyResult<Vec<u32>> {
    let a: PyReadonlyArray1<u32> = a
        .extract()
        .map_err(|_| bad(format!("\"{key}\" is not a 1-D array of uint32")))?;
    Ok(a.as_slice()
        .map_or_else(|_| a.as_array().to_vec(), <[u32]>::to_vec))
}

/// The fitted surface of a state [`state`] made.
pub fn from_state(d: &Bound<'_, PyDict>) -> PyResult<Fitted> {
    let fit = fit_from_state(d)?;
    if d.get_item("scan_points")?.is_none() {
        return Ok(fit);
    }
    let spacing: f64 = number(d, "scan_spacing")?;
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(bad(format!("\"scan_spacing\" {spacing}")));
    }
    let settings = ScanSettings {
        near: number(d, "scan_near")?,
        far: number(d, "scan_far")?,
        ..ScanSettings::default()
    };
    if !(settings.near >= 0.0 && settings.far > settings.near && settings.far.is_finite()) {
        return Err(bad("\"scan_near\" and \"scan_far\" are not 0 ≤ near < far"));
    }
    let points = points_of(d, "scan_points")?;
    let normals = points_of(d, "scan_normals")?;
    let areas = values_of(d, "scan_areas")?;
    if normals.len() != points.len() || areas.len() != points.len() {
        return Err(bad(
            "\"scan_points\", \"scan_normals\" and \"scan_areas\" differ in length",
        ));
    }
    let distances = values_of(d, "scan_distances")?;
    let [mean, p99, max]: [f64; 3] = distances
        .try_into()
        .map_err(|_| bad("\"scan_distances\" needs 3 numbers"))?;
    let report = ScanReport {
        points: number(d, "scan_given_points")?,
        outliers: indices_named(&item(d, "scan_outliers")?, "scan_outliers")?,
        spacing,
        noise: number(d, "scan_noise")?,
        normals_corrected: number(d, "scan_normals_corrected")?,
        turned_outward: number(d, "scan_turned_outward")?,
        normals_estimated: match d.get_item("scan_normals_estimated")? {
            Some(v) => v.extract()?,
            None => false,
        },
        distance_mean: mean,
        distance_p99: p99,
        distance_max: max,
    };
    let py = d.py();
    let guard = super::interrupt::run(py, None, false, || {
        guard_of(points, normals, areas, spacing, &settings)
    })?;
    Ok(Fitted::Scan(Arc::new(ScanSurface::from_parts(
        fit,
        Arc::new(guard),
        report,
    ))))
}

/// A global or partition fit from a state's entries.
fn fit_from_state(d: &Bound<'_, PyDict>) -> PyResult<Fitted> {
    let format: i64 = number(d, "format")?;
    if !(1..=FORMAT).contains(&format) {
        return Err(bad(format!(
            "format {format}; this version reads formats 1 to {FORMAT}"
        )));
    }
    let method: String = number(d, "method")?;
    let kernel_name: String = number(d, "kernel")?;
    let kernel = Kernel::parse(&kernel_name).map_err(|_| bad(format!("kernel {kernel_name:?}")))?;
    let constraints = constraints_of(d)?;
    let residual: f64 = number(d, "residual")?;
    match method.as_str() {
        "global" => {
            let parts = SurfaceParts {
                kernel,
                centers: points_of(d, "centers")?,
                weights: values_of(d, "weights")?,
                polynomial: four(values_of(d, "polynomial")?, "polynomial")?,
                shift: DVec3::from_array(
                    values_of(d, "shift")?
                        .try_into()
                        .map_err(|_| bad("\"shift\" needs 3 numbers"))?,
                ),
                scale: number(d, "scale")?,
                normalized_centers: points_of(d, "normalized_centers")?,
                normalized_weights: values_of(d, "normalized_weights")?,
                normalized_polynomial: four(
                    values_of(d, "normalized_polynomial")?,
                    "normalized_polynomial",
                )?,
                constraints,
                residual,
                factorization: number(d, "factorization")?,
            };
            let s = d.py().detach(|| VariationalSurface::from_parts(parts))?;
            Ok(Fitted::Global(Arc::new(s)))
        }
        "partition" => {
            let settings = PartitionSettings {
                max_per_leaf: number(d, "max_per_leaf")?,
                overlap: number(d, "overlap")?,
                max_patch: number(d, "max_patch")?,
                min_points: number(d, "min_points")?,
                fit: FitSettings {
                    kernel,
                    smoothing: number(d, "smoothing")?,
                    memory_limit: number(d, "memory_limit")?,
                },
            };
            let (flat, tree) = (FlatPatches::read(d)?, tree_of(d)?);
            let py = d.py();
            let patches = super::interrupt::detach(py, || flat.patches(kernel))?;
            let parts = PartitionParts {
                settings,
                constraints,
                patches,
                residual,
                tree,
            };
            // Building the surface (its octree, patches and cover) stops on Ctrl-C.
            let s = super::interrupt::run(py, None, false, || PartitionSurface::from_parts(parts))?;
            Ok(Fitted::Partition(Arc::new(s)))
        }
        other => Err(bad(format!("method {other:?}"))),
    }
}
