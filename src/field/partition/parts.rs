//! A partition-of-unity surface as plain numbers and back, bit for bit: the constraints, the
//! settings and every patch's fit; the octree and the patches covering each leaf are built
//! again from them (both depend only on the constraints, the settings and the patches' balls).

use super::{patches, Octree, PartitionSettings, PartitionSurface, Patch};
use crate::error::Result;
use crate::field::constraints::Constraints;
use crate::field::rbf::{bad_state, SurfaceParts, VariationalSurface};
use glam::DVec3;

/// One patch: its ball, its counts and its fit.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchParts {
    pub centre: DVec3,
    pub radius: f64,
    pub inside: usize,
    pub size: usize,
    pub fit: SurfaceParts,
}

/// Everything a [`PartitionSurface`] holds besides what is built again from it.
#[derive(Clone, Debug, PartialEq)]
pub struct PartitionParts {
    pub settings: PartitionSettings,
    pub constraints: Constraints,
    pub patches: Vec<PatchParts>,
    pub residual: f64,
}

impl PartitionSurface {
    /// The surface as plain numbers (see [`PartitionParts`]).
    pub fn parts(&self) -> PartitionParts {
        PartitionParts {
            settings: self.settings,
            constraints: self.constraints.clone(),
            patches: self
                .patches
                .iter()
                .map(|p| PatchParts {
                    centre: p.centre,
                    radius: p.radius,
                    inside: p.inside,
                    size: p.size,
                    fit: p.fit.parts(),
                })
                .collect(),
            residual: self.residual,
        }
    }

    /// The surface [`PartitionSurface::parts`] gave: it evaluates to the same bits. Errors
    /// (naming `state`) for parts no fit makes.
    pub fn from_parts(p: PartitionParts) -> Result<Self> {
        p.settings.check()?;
        let c = &p.constraints;
        if c.values.len() != c.points.len() || c.boundary > c.points.len() || c.boundary == 0 {
            return Err(bad_state("constraint points and values differ in length"));
        }
        if !c.points.iter().all(|v| v.is_finite()) {
            return Err(bad_state("non-finite constraint points"));
        }
        if p.patches.is_empty() {
            return Err(bad_state("no patches"));
        }
        let patches = p
            .patches
            .into_iter()
            .map(|q| {
                if !(q.centre.is_finite() && q.radius.is_finite() && q.radius > 0.0) {
                    return Err(bad_state("a patch's ball is not finite"));
                }
                Ok(Patch {
                    centre: q.centre,
                    radius: q.radius,
                    inside: q.inside,
                    size: q.size,
                    fit: VariationalSurface::from_parts(q.fit)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let tree: Octree = Self::tree(c, &p.settings);
        let (cover_start, cover) = patches::cover(&tree, &patches);
        Ok(PartitionSurface {
            settings: p.settings,
            constraints: p.constraints,
            tree,
            patches,
            cover_start,
            cover,
            residual: p.residual,
        })
    }
}
