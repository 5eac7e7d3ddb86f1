//! Making a blob field and changing it: the primitives' arrays checked and filled
//! ([`PerPrimitive`]), moved in place by [`BlobField::update`] (the voxel lists rebuilt in place
//! once built), and the per-primitive records point queries read, packed on the first query.

use super::{BlobField, BlobSettings, Packed};
use crate::error::{check_finite_points, Error, Result};
use glam::DVec3;

/// A scalar or one value per primitive.
#[derive(Clone, Debug)]
pub enum PerPrimitive<'a> {
    /// The same value for every primitive.
    All(f64),
    /// One value per primitive, in the primitives' order.
    Each(&'a [f64]),
}

impl PerPrimitive<'_> {
    pub(super) fn fill(
        &self,
        name: &'static str,
        n: usize,
        out: &mut Vec<f64>,
        positive: bool,
    ) -> Result<()> {
        out.clear();
        match self {
            PerPrimitive::All(v) => out.resize(n, *v),
            PerPrimitive::Each(v) => {
                if v.len() != n {
                    return Err(Error::invalid(
                        name,
                        format!(
                            "need one value per center or a scalar: {} values for {n} centers",
                            v.len()
                        ),
                    ));
                }
                out.extend_from_slice(v);
            }
        }
        if let Some(i) = out
            .iter()
            .position(|v| !v.is_finite() || (positive && *v <= 0.0))
        {
            return Err(Error::invalid(
                name,
                format!(
                    "entry {i} is {}; must be finite{}",
                    out[i],
                    if positive { " and positive" } else { "" }
                ),
            ));
        }
        // Radii: the kernels compare squared distances with r², so 1/r² must be a normal float64.
        if positive {
            if let Some(i) = out.iter().position(|v| !(1.0 / (v * v)).is_normal()) {
                return Err(Error::invalid(
                    name,
                    format!(
                        "entry {i} is {:e}; must lie between 1e-154 and 1e154 (its square a normal float64)",
                        out[i]
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl BlobField {
    /// A blob field with primitives at `centers`, radii of influence `radii`, strengths
    /// (the paper's A_i) `strengths`, and the surface at potential `threshold`.
    pub fn new(
        centers: &[DVec3],
        radii: PerPrimitive,
        strengths: PerPrimitive,
        threshold: f64,
        settings: BlobSettings,
    ) -> Result<Self> {
        if !(threshold.is_finite() && threshold > 0.0) {
            return Err(Error::invalid(
                "threshold",
                format!("must be positive and finite, got {threshold}"),
            ));
        }
        if !(settings.voxel_size.is_finite() && settings.voxel_size > 0.0) {
            return Err(Error::invalid(
                "voxel_size",
                format!("must be positive and finite, got {}", settings.voxel_size),
            ));
        }
        let mut b = BlobField {
            threshold,
            settings,
            ..Default::default()
        };
        b.update(centers, Some(radii), Some(strengths))?;
        Ok(b)
    }

    /// Moves the primitives (and optionally changes radii and strengths), then rebuilds the voxel
    /// lists in place. The number of primitives may change; when it does not, nothing is
    /// reallocated.
    pub fn update(
        &mut self,
        centers: &[DVec3],
        radii: Option<PerPrimitive>,
        strengths: Option<PerPrimitive>,
    ) -> Result<()> {
        if self.shapes.is_some() {
            return self.update_shaped(centers, radii, strengths);
        }
        self.update_primitives(centers, radii, strengths)
    }

    /// [`BlobField::update`] of the primitives' arrays (`radii`: the spheres' radii).
    pub(super) fn update_primitives(
        &mut self,
        centers: &[DVec3],
        radii: Option<PerPrimitive>,
        strengths: Option<PerPrimitive>,
    ) -> Result<()> {
        check_finite_points("centers", centers)?;
        crate::spatial::check_far("centers", centers)?;
        let n = centers.len();
        let mut r = std::mem::take(&mut self.radii);
        let mut a = std::mem::take(&mut self.strengths);
        let res = (|| {
            match radii {
                Some(p) => p.fill("radii", n, &mut r, true)?,
                None if r.len() != n => {
                    return Err(Error::invalid(
                        "radii",
                        format!(
                            "{n} centers but {} radii: pass radii when the count changes",
                            r.len()
                        ),
                    ))
                }
                None => {}
            }
            match strengths {
                Some(p) => p.fill("strengths", n, &mut a, false)?,
                None if a.len() != n => {
                    return Err(Error::invalid(
                        "strengths",
                        format!(
                            "{n} centers but {} strengths: pass strengths when the count changes",
                            a.len()
                        ),
                    ))
                }
                None => {}
            }
            // The voxel grid spans the spheres of influence: their box must be a finite size.
            let (lo, hi) = centers.iter().zip(&r).fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), (c, r)| (lo.min(*c - *r), hi.max(*c + *r)),
            );
            if n > 0 && !(hi - lo).is_finite() {
                return Err(Error::invalid(
                    "radii",
                    format!(
                        "the primitives' spheres span from {} to {}, wider than a float64 can hold",
                        crate::spatial::short(lo),
                        crate::spatial::short(hi)
                    ),
                ));
            }
            Ok(())
        })();
        self.radii = r;
        self.strengths = a;
        res?;
        self.centers.clear();
        self.centers.extend_from_slice(centers);
        self.inv_r2.clear();
        self.inv_r2.extend(self.radii.iter().map(|r| 1.0 / (r * r)));
        self.repack();
        let side = self.voxel_side();
        if let Some(grid) = self.grid.get_mut() {
            grid.rebuild(&self.centers, &self.radii, side);
        }
        Ok(())
    }

    /// The voxels' side: [`BlobSettings::voxel_size`] times the mean radius.
    pub(super) fn voxel_side(&self) -> f64 {
        let n = self.radii.len();
        let mean_r = if n > 0 {
            self.radii.iter().sum::<f64>() / n as f64
        } else {
            1.0
        };
        self.settings.voxel_size * mean_r
    }

    /// Replaces the strengths (one per primitive or a scalar), keeping centres, radii and the
    /// voxel lists.
    pub fn set_strengths(&mut self, strengths: PerPrimitive) -> Result<()> {
        let mut a = std::mem::take(&mut self.strengths);
        let res = strengths.fill("strengths", self.centers.len(), &mut a, false);
        if res.is_ok() {
            self.strengths = a;
            self.repack();
        } else {
            self.strengths = a;
        }
        res
    }

    /// Refills [`BlobField::packed`] in place from the per-primitive arrays when it is built.
    fn repack(&mut self) {
        if let Some(packed) = self.packed.get_mut() {
            packed.clear();
            packed.extend((0..self.centers.len()).map(|i| Packed {
                center: self.centers[i],
                inv_r2: self.inv_r2[i],
                strength: self.strengths[i],
            }));
        }
    }

    /// The primitives packed for point queries, built on the first call.
    pub(super) fn packed(&self) -> &[Packed] {
        self.packed.get_or_init(|| {
            (0..self.centers.len())
                .map(|i| Packed {
                    center: self.centers[i],
                    inv_r2: self.inv_r2[i],
                    strength: self.strengths[i],
                })
                .collect()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::blob::kernel::BlobKernel;
    use crate::lattice::Lattice;
    use crate::testing::{random_points, sized_blobs};

    #[test]
    fn sparse_builds_neither_voxel_lists_nor_packed_primitives() {
        use crate::polygonize::{sparse, Settings};
        let l = Lattice::cubic(DVec3::splat(-1.0), DVec3::splat(1.0), 40).unwrap();
        for normals in [false, true] {
            let b = sized_blobs(60, 23, BlobKernel::Triquet);
            let settings = Settings {
                normals,
                ..Default::default()
            };
            let crate::polygonize::Polygonized {
                mesh: m, stats: _, ..
            } = sparse::polygonize(&b, &l, &settings).unwrap();
            assert!(!m.triangles.is_empty());
            assert_eq!(m.normals.len(), if normals { m.vertices.len() } else { 0 });
            assert!(b.grid.get().is_none() && b.packed.get().is_none());
            // Built on the first point query, the same lists as a field built with them.
            let p = DVec3::new(0.1, 0.2, 0.3);
            assert_eq!(b.potential(p), b.potential_brute_force(p));
            assert!(b.grid.get().is_some() && b.packed.get().is_some());
        }
    }

    #[test]
    fn update_moves_without_reallocating() {
        let mut b = sized_blobs(200, 21, BlobKernel::Triquet);
        let before = b.grid().capacity_bytes();
        for k in 0..20 {
            let c: Vec<DVec3> = b
                .centers()
                .iter()
                .map(|p| *p + DVec3::splat(0.001 * k as f64))
                .collect();
            b.update(&c, None, None).unwrap();
        }
        // Capacity may settle after the first rebuilds but must not keep growing.
        let mid = b.grid().capacity_bytes();
        for k in 0..20 {
            let c: Vec<DVec3> = b
                .centers()
                .iter()
                .map(|p| *p - DVec3::splat(0.001 * k as f64))
                .collect();
            b.update(&c, None, None).unwrap();
        }
        assert!(b.grid().capacity_bytes() <= mid.max(before) * 2);
        for p in random_points(500, -1.0, 1.0, 2) {
            assert!((b.potential(p) - b.potential_brute_force(p)).abs() < 1e-12);
        }
    }

    #[test]
    fn bad_input_refused() {
        let c = [DVec3::ZERO];
        assert!(BlobField::new(
            &c,
            PerPrimitive::All(-1.0),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default()
        )
        .is_err());
        assert!(BlobField::new(
            &c,
            PerPrimitive::All(1.0),
            PerPrimitive::All(1.0),
            0.0,
            BlobSettings::default()
        )
        .is_err());
        assert!(BlobField::new(
            &c,
            PerPrimitive::Each(&[1.0, 2.0]),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default()
        )
        .is_err());
        assert!(BlobField::new(
            &[DVec3::NAN],
            PerPrimitive::All(1.0),
            PerPrimitive::All(1.0),
            0.5,
            BlobSettings::default()
        )
        .is_err());
    }
}
