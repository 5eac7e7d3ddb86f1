//! Partition-of-unity variational surfaces, for data too large for one dense system (Ohtake et
//! al.'s multi-level partition of unity, with variational patches instead of quadrics).
//!
//! - [`octree`]: an octree over the constraints (boundary and normal constraints together),
//!   split until each leaf holds at most [`PartitionSettings::max_per_leaf`] of them and the ball of
//!   its patch at most [`PartitionSettings::max_patch`]; its cube covers the constraints and the
//!   surface's default polygonization bounds.
//! - [`patches`]: one patch per leaf, a ball of radius [`PartitionSettings::overlap`] × the leaf's
//!   half-diagonal around its centre, fitted with r³ + linear (as
//!   [`VariationalSurface`](crate::field::rbf::VariationalSurface)) to every constraint in the ball
//!   (completed, when they are fewer than [`PartitionSettings::min_points`], by constraints spread over a
//!   larger ball, from the subsampled levels of [`coarse`]; a ball with no constraint, in a
//!   fit with normal constraints, gets a plane that carries the sign of space, [`empty`]);
//!   patches are solved in parallel.
//! - [`blend`]: f = Σ w_i f_i / Σ w_i with compactly supported C² weights. Each patch whose
//!   weight is non-zero at a constraint interpolates it, so the blend interpolates every
//!   constraint to the patches' residual.

pub mod blend;
pub mod coarse;
mod cut;
pub mod empty;
pub mod octree;
mod parts;
pub mod patches;

pub use parts::{PartitionParts, PatchParts};

use super::constraints::{self, bounding_box, Constraints};
use super::kernel::Kernel;
use super::Field;
use crate::error::{Error, Result};
use glam::DVec3;
use octree::Octree;
use patches::Patch;
use std::borrow::Cow;

/// How a partition-of-unity surface is fitted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PartitionSettings {
    /// Leaves split until they hold at most this many constraints. With the defaults a patch's
    /// support then holds about 60–75 constraints, and its completed system about 105–125
    /// (10⁶ and 10⁵ points sampled on a mesh).
    pub max_per_leaf: usize,
    /// Support radius of a leaf's patch over the leaf's half-diagonal (> 1, so that the supports
    /// overlap and each covers its leaf). A patch's system grows with its square on a surface,
    /// and its factorization with the cube of that.
    pub overlap: f64,
    /// Leaves also split until the ball of their patch holds at most this many constraints;
    /// completed systems (see [`patches`]) hold at most 3/2 of it.
    pub max_patch: usize,
    /// Patches whose support holds fewer constraints complete their system with constraints
    /// from outside it (see [`patches`] and [`coarse`]).
    pub min_points: usize,
    /// Each patch's fit (kernel, smoothing); its `memory_limit` refuses fits whose patches (kept,
    /// and the dense systems being solved) would need more bytes.
    pub fit: crate::field::rbf::FitSettings,
}

impl Default for PartitionSettings {
    fn default() -> Self {
        PartitionSettings {
            max_per_leaf: 64,
            overlap: 1.15,
            max_patch: 256,
            min_points: 128,
            fit: crate::field::rbf::FitSettings::default(),
        }
    }
}

impl PartitionSettings {
    fn check(&self) -> Result<()> {
        if self.max_per_leaf < 8 {
            return Err(Error::invalid(
                "max_per_leaf",
                format!("must be at least 8, got {}", self.max_per_leaf),
            ));
        }
        if !(self.overlap.is_finite() && self.overlap > 1.0) {
            return Err(Error::invalid(
                "overlap",
                format!("must be finite and above 1, got {}", self.overlap),
            ));
        }
        if self.max_patch < self.max_per_leaf {
            return Err(Error::invalid(
                "max_patch",
                format!(
                    "must be at least max_per_leaf ({}), got {}",
                    self.max_per_leaf, self.max_patch
                ),
            ));
        }
        if self.min_points < 8 {
            return Err(Error::invalid(
                "min_points",
                format!("must be at least 8, got {}", self.min_points),
            ));
        }
        if !(self.fit.smoothing.is_finite() && self.fit.smoothing >= 0.0) {
            return Err(Error::invalid(
                "smoothing",
                format!(
                    "must be finite and non-negative, got {}",
                    self.fit.smoothing
                ),
            ));
        }
        Ok(())
    }
}

/// A partition-of-unity variational surface: negative inside, positive outside (when the
/// normals given point out of the solid).
#[derive(Clone, Debug)]
pub struct PartitionSurface {
    settings: PartitionSettings,
    /// The constraints; for a whole surface without their points, which `centres` holds in
    /// the octree's order (see [`PartitionSurface::constraint_points`]).
    constraints: Constraints,
    /// The bounding box of the data points.
    data_box: (DVec3, DVec3),
    tree: Octree,
    /// Whether this is a [`PartitionSurface::cut`], whose octree is not built from its
    /// constraints (and so is part of its [`PartitionSurface::parts`]).
    cut: bool,
    patches: Vec<Patch>,
    /// The points the patches' indices name: the constraint points in the octree's order
    /// (`tree.order`) for a whole surface, a cut's constraint points for a cut (whose octree
    /// holds no points), so that a patch's centres lie in a few runs of memory.
    centres: Vec<DVec3>,
    /// Patches covering each leaf: `cover[cover_start[l]..cover_start[l + 1]]`, increasing.
    cover_start: Vec<u32>,
    cover: Vec<u32>,
    residual: f64,
}

impl PartitionSurface {
    /// Fits a surface to `points` with outward `normals`, with the constraints of
    /// [`constraints::place`].
    pub fn fit(
        points: &[DVec3],
        normals: &[DVec3],
        placement: &constraints::ConstraintSettings,
        settings: &PartitionSettings,
    ) -> Result<Self> {
        settings.check()?;
        let c = constraints::place(points, normals, placement)?;
        Self::solve(c, settings).map_err(|e| constraints::diagnose_far("points", points, e))
    }

    /// Fits a surface to the vertices of a triangle mesh, as
    /// [`VariationalSurface::from_mesh`](crate::field::rbf::VariationalSurface::from_mesh).
    pub fn from_mesh(
        vertices: &[DVec3],
        faces: &[[u32; 3]],
        placement: &constraints::ConstraintSettings,
        settings: &PartitionSettings,
    ) -> Result<Self> {
        settings.check()?;
        let (v, f, n) = constraints::mesh_vertices_normals(vertices, faces)?;
        let caps = constraints::crease_caps(&v, &f, &n);
        let c = constraints::place_capped(&v, &n, placement, Some(&caps))?;
        Self::solve(c, settings).map_err(|e| constraints::diagnose_far("vertices", &v, e))
    }

    /// Interpolates arbitrary values at arbitrary points (no normal constraints added).
    pub fn interpolate(
        points: &[DVec3],
        values: &[f64],
        merge_distance: Option<f64>,
        settings: &PartitionSettings,
    ) -> Result<Self> {
        settings.check()?;
        let c = constraints::interpolation_data(points, values, merge_distance)?;
        Self::solve(c, settings).map_err(|e| constraints::diagnose_far("points", points, e))
    }

    /// The cube, centred on the data's bounding box, covering the default polygonization bounds
    /// (half-side 0.6 × the data's largest side) and every constraint: (centre, half-side).
    fn cube(c: &Constraints) -> (DVec3, f64) {
        let (lo, hi) = bounding_box(&c.points[..c.boundary]);
        let centre = (lo + hi) * 0.5;
        let reach = c
            .points
            .iter()
            .map(|p| (*p - centre).abs().max_element())
            .fold(0.6 * (hi - lo).max_element(), f64::max);
        (centre, reach * (1.0 + 1e-9))
    }

    /// The octree of the constraints: split until each leaf holds at most `max_per_leaf` and
    /// the ball of its patch at most `max_patch` of them. Errors with
    /// [`Error::Interrupted`](crate::error::Error::Interrupted) when the calling thread's token
    /// is set (checked between the two octrees it builds).
    fn tree(c: &Constraints, settings: &PartitionSettings) -> Result<Octree> {
        let (centre, half) = Self::cube(c);
        // A first octree counts the constraints in the balls of the final one's nodes, which
        // splits it further where a ball holds too many.
        let counts = Octree::new(&c.points, centre, half, settings.max_per_leaf);
        crate::cancel::check()?;
        Ok(counts.refined(|counts, n| {
            counts.more_within_than(
                &c.points,
                n.centre,
                settings.overlap * n.half_diagonal(),
                settings.max_patch,
            )
        }))
    }

    /// The coarse levels of the constraints, over the fit's octree `tree`.
    fn levels<'t>(
        tree: &'t Octree,
        c: &Constraints,
        settings: &PartitionSettings,
    ) -> Result<coarse::Levels<'t>> {
        let (centre, half) = Self::cube(c);
        let (smallest, max_per_leaf) = (settings.max_patch, settings.max_per_leaf);
        coarse::levels(tree, c, smallest, centre, half, max_per_leaf)
    }

    fn solve(c: Constraints, settings: &PartitionSettings) -> Result<Self> {
        crate::cancel::check()?;
        let tree = Self::tree(&c, settings)?;
        let levels = Self::levels(&tree, &c, settings)?;
        let oriented = empty::oriented(&c).then(|| patches::Oriented {
            first_off: c.boundary,
            largest_offset: c.offsets.iter().copied().fold(0.0, f64::max),
        });
        let supports = patches::supports(&tree, &c.points, &levels, settings, oriented)?;
        let sizes: Vec<usize> = supports.iter().map(|s| s.size()).collect();
        let bytes = patches::estimate_bytes(&sizes, rayon::current_num_threads())
            + (c.points.len() * (48 + 24)) as u64
            + (tree.nodes.len() * std::mem::size_of::<octree::Node>()) as u64;
        patches::check_memory(bytes, settings.fit.memory_limit)?;
        // From here on the points are read from the octree's copy.
        let data_box = constraints::bulk_bounding_box(&c.points[..c.boundary]);
        let mut c = c;
        drop(std::mem::take(&mut c.points));
        let fitted = patches::fit(&tree, &c, &levels, &supports, settings)?;
        // Freed before the cover is built, which would otherwise come on top of them.
        drop((levels, supports));
        crate::cancel::check()?;
        let residual = fitted.iter().map(|p| p.fit.residual()).fold(0.0, f64::max);
        let (cover_start, cover) = patches::cover(&tree, &fitted);
        // The kept octree answers no more queries on points (evaluation only descends it): its
        // copy of them is what the patches index.
        let mut tree = tree;
        let centres = tree.take_copy();
        Ok(PartitionSurface {
            settings: *settings,
            constraints: c,
            data_box,
            tree,
            cut: false,
            patches: fitted,
            centres,
            cover_start,
            cover,
            residual,
        })
    }

    /// The settings of the fit.
    pub fn settings(&self) -> &PartitionSettings {
        &self.settings
    }
    /// The kernel.
    pub fn kernel(&self) -> Kernel {
        self.settings.fit.kernel
    }
    /// The constraints the surface interpolates (for a whole surface, their points gathered
    /// from the octree's order, in which the surface keeps them).
    pub fn constraints(&self) -> Cow<'_, Constraints> {
        match self.constraint_points() {
            Cow::Borrowed(_) => Cow::Borrowed(&self.constraints),
            Cow::Owned(points) => Cow::Owned(Constraints {
                points,
                ..self.constraints.clone()
            }),
        }
    }
    /// The constraint points, in the constraints' order.
    pub fn constraint_points(&self) -> Cow<'_, [DVec3]> {
        if self.constraints.points.len() == self.centres.len() {
            return Cow::Borrowed(&self.constraints.points);
        }
        let mut points = vec![DVec3::ZERO; self.centres.len()];
        for (&i, p) in self.tree.order.iter().zip(&self.centres) {
            points[i as usize] = *p;
        }
        Cow::Owned(points)
    }
    /// The number of constraints.
    pub fn constraint_count(&self) -> usize {
        self.constraints.values.len()
    }
    /// The number of data points merged into others before the fit.
    pub fn merged(&self) -> usize {
        self.constraints.merged
    }
    /// Largest |f_i(c) − v| over the patches and their constraints, as measured after each
    /// patch's fit (the blend's error at a constraint is at most this).
    pub fn residual(&self) -> f64 {
        self.residual
    }
    /// The patches (centre, support radius, numbers of constraints, fit).
    pub fn patches(&self) -> &[Patch] {
        &self.patches
    }
    /// The octree.
    pub fn octree(&self) -> &Octree {
        &self.tree
    }
    /// The constraint (its index in [`PartitionSurface::constraints`]) at position `k` of the
    /// points the patches index.
    pub fn constraint_at(&self, k: u32) -> u32 {
        match self.tree.order.is_empty() {
            true => k,
            false => self.tree.order[k as usize],
        }
    }
    /// Bounding box of the boundary constraints (the data points) within
    /// [`crate::spatial::OUTSIDE`] extents of their bulk ([`constraints::bulk_bounding_box`]).
    pub fn data_bounding_box(&self) -> (DVec3, DVec3) {
        self.data_box
    }
    /// The normalised blending weights w_i(x) / Σ w_i(x) of the patches whose support holds
    /// `x`, in increasing patch order (empty where no support reaches).
    pub fn weights_at(&self, x: DVec3) -> Vec<(u32, f64)> {
        let l = self.tree.leaf_of(x);
        let mut w: Vec<(u32, f64)> = self.cover
            [self.cover_start[l as usize] as usize..self.cover_start[l as usize + 1] as usize]
            .iter()
            .map(|&i| {
                let p = &self.patches[i as usize];
                (i, blend::weight(x, p.centre, p.radius).0)
            })
            .filter(|(_, w)| *w > 0.0)
            .collect();
        let total: f64 = w.iter().map(|(_, w)| w).sum();
        w.iter_mut().for_each(|(_, v)| *v /= total);
        w
    }
}

impl Field for PartitionSurface {
    /// The boundary constraints (the data points), as for a global fit.
    fn starts(&self, _cell: f64) -> Option<crate::field::Starts> {
        Some(super::boundary_starts(&self.constraints()))
    }
    fn value(&self, p: DVec3) -> f64 {
        let mut out = [0.0];
        self.blend(&[p], &mut out, None);
        out[0]
    }

    fn gradient(&self, p: DVec3) -> DVec3 {
        let mut v = [0.0];
        let mut g = [DVec3::ZERO];
        self.blend(&[p], &mut v, Some(&mut g));
        g[0]
    }

    fn values(&self, points: &[DVec3], out: &mut [f64]) {
        self.blend(points, out, None);
    }

    fn gradients(&self, points: &[DVec3], out: &mut [DVec3]) {
        let mut v = vec![0.0; points.len()];
        self.blend(points, &mut v, Some(out));
    }
}

#[cfg(test)]
mod tests;
