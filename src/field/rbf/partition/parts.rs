//! A partition-of-unity surface as plain numbers and back, bit for bit: the constraints, the
//! settings and every patch's fit, and for a cut its octree; the octree of a whole surface and
//! the patches covering each leaf are built again from them (they depend only on the
//! constraints, the settings and the patches' balls).

use super::octree::Node;
use super::{patches, Octree, PartitionSettings, PartitionSurface, Patch};
use crate::error::Result;
use crate::field::rbf::constraints::{bulk_bounding_box, Constraints};
use crate::field::rbf::{bad_state, PatchFit, SurfaceParts};
use glam::DVec3;

/// One patch: its ball, its counts and its fit.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PatchParts {
    /// Centre of the patch's support.
    pub centre: DVec3,
    /// Support radius: the patch's weight is zero from this distance on.
    pub radius: f64,
    /// Constraints inside the support.
    pub inside: usize,
    /// Constraints the patch interpolates.
    pub size: usize,
    /// The fit's numbers; its normalised centres only for a patch with centres of its own.
    pub fit: SurfaceParts,
    /// The constraints its centres are (indices into [`PartitionParts::constraints`]); empty
    /// for a patch with centres of its own.
    pub index: Vec<u32>,
}

/// Everything a [`PartitionSurface`] holds besides what is built again from it.
#[derive(Clone, Debug, PartialEq)]
pub struct PartitionParts {
    /// How the surface was fitted.
    pub settings: PartitionSettings,
    /// The constraints of all patches.
    pub constraints: Constraints,
    /// The patches.
    pub patches: Vec<PatchParts>,
    /// Largest residual over the patches and their constraints.
    pub residual: f64,
    /// The octree's nodes, for a [`PartitionSurface::cut`] (whose octree is not the one its
    /// constraints give); `None` for a whole surface.
    pub tree: Option<Vec<Node>>,
}

impl PartitionSurface {
    /// The surface as plain numbers (see [`PartitionParts`]).
    pub fn parts(&self) -> PartitionParts {
        PartitionParts {
            settings: self.settings,
            constraints: self.constraints().into_owned(),
            patches: self
                .patches
                .iter()
                .map(|p| {
                    let (fit, index) = p.fit.parts();
                    let index = index.iter().map(|&k| self.constraint_at(k)).collect();
                    PatchParts {
                        centre: p.centre,
                        radius: p.radius,
                        inside: p.inside,
                        size: p.size,
                        fit,
                        index,
                    }
                })
                .collect(),
            residual: self.residual,
            tree: self.cut.then(|| self.tree.nodes.clone()),
        }
    }

    /// The surface [`PartitionSurface::parts`] gave: it evaluates to the same bits. Errors
    /// (naming `state`) for parts no fit makes, and with
    /// [`Interrupted`](crate::error::Error::Interrupted) when the calling thread's token is set.
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
        // The octree and the patches' cover are sized from the points: far points are refused
        // as a fit refuses them, and so are patch balls reaching that far.
        crate::spatial::check_far("constraint_points", &c.points).map_err(bad_state)?;
        if let Some(bulk) = crate::spatial::Bulk::of(&c.points) {
            let reach = crate::spatial::FAR * bulk.extent;
            let far = |q: &PatchParts| {
                q.centre.is_finite()
                    && q.radius.is_finite()
                    && (bulk.ratio(q.centre) > crate::spatial::FAR || q.radius > reach)
            };
            if p.patches.iter().any(far) {
                return Err(bad_state(format!(
                    "a patch's ball reaches more than {reach:.3e} from the constraint points"
                )));
            }
        }
        let cut = p.tree.is_some();
        let mut tree: Octree = match p.tree {
            Some(nodes) => Octree::from_nodes(checked_nodes(nodes)?),
            None => Self::tree(c, &p.settings)?,
        };
        crate::cancel::check()?;
        // The patches index the constraints in the octree's order (a cut's octree has none).
        let centres = match cut {
            true => c.points.clone(),
            false => tree.take_copy(),
        };
        let rank = (!cut).then(|| patches::inverse(&tree.order));
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
                    fit: {
                        let mut fit = PatchFit::from_parts(q.fit, q.index, c.points.len())?;
                        if let Some(rank) = &rank {
                            fit.renumber(rank);
                        }
                        fit
                    },
                })
            })
            .collect::<Result<Vec<_>>>()?;
        crate::cancel::check()?;
        let (cover_start, cover) = patches::cover(&tree, &patches);
        // A whole surface keeps its points only in the octree's order (`centres`).
        let data_box = bulk_bounding_box(&c.points[..c.boundary]);
        let constraints = match cut {
            true => p.constraints,
            false => Constraints {
                points: Vec::new(),
                ..p.constraints
            },
        };
        Ok(PartitionSurface {
            settings: p.settings,
            constraints,
            data_box,
            tree,
            cut,
            patches,
            centres,
            cover_start,
            cover,
            residual: p.residual,
        })
    }
}

/// `nodes` when they form an octree: a root, finite cubes, and each inner node's eight
/// children after it.
fn checked_nodes(nodes: Vec<Node>) -> Result<Vec<Node>> {
    let n = nodes.len();
    let ok = n > 0
        && nodes.iter().enumerate().all(|(k, node)| {
            node.centre.is_finite()
                && node.half.is_finite()
                && node.half > 0.0
                && (node.is_leaf()
                    || (node.children as usize > k && node.children as usize + 8 <= n))
        });
    if !ok {
        return Err(bad_state("the octree's nodes do not form an octree"));
    }
    // Children come after their parent: one pass gives each node's depth (the deepest it is
    // reached at), which the octree's walks bound.
    let mut depth = vec![0u32; n];
    for (k, node) in nodes.iter().enumerate() {
        if !node.is_leaf() {
            for c in node.children as usize..node.children as usize + 8 {
                depth[c] = depth[c].max(depth[k] + 1);
            }
        }
    }
    if depth.iter().any(|&d| d > super::octree::MAX_DEPTH) {
        return Err(bad_state("the octree is deeper than 24 levels"));
    }
    Ok(nodes)
}
