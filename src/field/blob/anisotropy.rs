//! Anisotropic kernels for particle fields (Yu & Turk 2013, "Reconstructing surfaces of
//! particle-based fluids using anisotropic kernels"): each particle's kernel stretched along the
//! principal axes of its neighbourhood.
//!
//! Per particle i, over its neighbours j within the neighbour radius rₙ (itself included), with
//! weights wᵢⱼ = 1 − (|xᵢ − xⱼ|/rₙ)³:
//! - the weighted mean x̂ᵢ = Σ wᵢⱼ xⱼ / Σ wᵢⱼ and covariance Cᵢ = Σ wᵢⱼ (xⱼ − x̂ᵢ)(xⱼ − x̂ᵢ)ᵀ / Σ wᵢⱼ;
//! - the kernel's centre x̄ᵢ = (1 − λ) xᵢ + λ x̂ᵢ (Laplacian smoothing of the centres);
//! - Cᵢ = V diag(σ₁, σ₂, σ₃) Vᵀ with σ₁ ≥ σ₂ ≥ σ₃; with at least N_ε neighbours (itself not
//!   counted) the stretch Σ̃ = k_s diag(σ₁, max(σ₂, σ₁/k_r), max(σ₃, σ₁/k_r)) / σ₁, else
//!   Σ̃ = k_n I. Yu & Turk divide by a constant (their k_s, 1400, holds its inverse), so that
//!   a full neighbourhood gives Σ̃ ≈ I; dividing by σ₁ gives the same inside the fluid and on
//!   flat surfaces (their tangential σ₁ is a full neighbourhood's), and keeps the longest
//!   axis k_s·H where the neighbours fill a corner or an edge, whose σ are all small (their
//!   kernels would shrink to specks that come apart from the body);
//! - the shape Sᵢ = V Σ̃⁻¹ Vᵀ: the kernel A·w(|Sᵢ (x − x̄ᵢ)|/H)·det Sᵢ reaches H·Σ̃ₖ along
//!   eigenvector k, and det Sᵢ keeps its integral that of the round kernel.

use crate::error::{Error, Result};
use crate::field::blob::densities::CellList;
use crate::knn::symmetric_eigen;
use glam::DVec3;
use rayon::prelude::*;

/// The options of Yu & Turk's anisotropic kernels ([`shapes`]); the names are theirs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnisotropySettings {
    /// The neighbour radius rₙ as a multiple of the kernel's compact support H. Default 2.0
    /// (Yu & Turk's rᵢ = 2hᵢ: four particle spacings at splashsurf's default support).
    pub neighbour_radius: f64,
    /// k_r: the largest ratio of a kernel's longest axis to its shortest. Default 4.
    pub k_r: f64,
    /// k_s: the stretched kernels' longest axis as a multiple of H (see the module docs).
    /// Default 1.
    pub k_s: f64,
    /// k_n: the radius of a round kernel (a particle with too few neighbours) as a multiple of
    /// H. Default 0.5.
    pub k_n: f64,
    /// N_ε: the fewest neighbours (the particle itself not counted) for a stretched kernel.
    /// Default 25 (about 270 inside the fluid at the default radius, 135 on a flat surface).
    pub min_neighbours: usize,
    /// λ: how far each kernel's centre moves towards its neighbours' weighted mean, in [0, 1].
    /// Default 0.9.
    pub smoothing: f64,
}

impl Default for AnisotropySettings {
    fn default() -> Self {
        AnisotropySettings {
            neighbour_radius: 2.0,
            k_r: 4.0,
            k_s: 1.0,
            k_n: 0.5,
            min_neighbours: 25,
            smoothing: 0.9,
        }
    }
}

impl AnisotropySettings {
    /// Errors naming the first setting out of its range.
    pub fn check(&self) -> Result<()> {
        for (name, v) in [
            ("neighbour_radius", self.neighbour_radius),
            ("k_s", self.k_s),
            ("k_n", self.k_n),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(
                    name,
                    format!("must be positive and finite, got {v}"),
                ));
            }
        }
        if !(self.k_r.is_finite() && self.k_r >= 1.0 && self.k_r <= MAX_STRETCH) {
            return Err(Error::invalid(
                "k_r",
                format!("must lie in [1, {MAX_STRETCH}], got {}", self.k_r),
            ));
        }
        if !(0.0..=1.0).contains(&self.smoothing) {
            return Err(Error::invalid(
                "smoothing",
                format!("must lie in [0, 1], got {}", self.smoothing),
            ));
        }
        Ok(())
    }
}

/// The largest k_r accepted (a kernel's axes within a factor of 100).
pub const MAX_STRETCH: f64 = 100.0;

/// Sorted particles per step (the call stops between steps when told to).
const STEP: usize = 1 << 15;

/// The kernels' centres x̄ᵢ and shapes Sᵢ (row-major 3×3, symmetric) of `particles` for
/// kernels of compact support `support` (see the module docs). Parallel; stops between steps
/// when the caller's [`crate::cancel`] token is set, and reports particles done.
pub fn shapes(
    particles: &[DVec3],
    support: f64,
    settings: &AnisotropySettings,
) -> Result<(Vec<DVec3>, Vec<[f64; 9]>)> {
    settings.check()?;
    let n = particles.len();
    if n == 0 {
        return Ok((Vec::new(), Vec::new()));
    }
    let radius = settings.neighbour_radius * support;
    crate::field::blob::densities::check_support("neighbour_radius", radius)?;
    // Cells of half the radius, five per axis around each particle: about 15.6 r³ of
    // candidates for the 4.2 r³ of the ball, where cells of r would take 27 r³.
    const REACH: usize = 2;
    let list = CellList::new(particles, radius / REACH as f64);
    let mut centres = vec![DVec3::ZERO; n];
    let mut forms = vec![[0.0; 9]; n];
    let mut sorted_out: Vec<(DVec3, [f64; 9])> = vec![(DVec3::ZERO, [0.0; 9]); n];
    for (step, out) in sorted_out.chunks_mut(STEP).enumerate() {
        crate::cancel::check()?;
        let first = step * STEP;
        let own = &list.sorted[first..first + out.len()];
        out.par_iter_mut().zip(own.par_iter()).for_each(|(o, &p)| {
            let hood = neighbourhood(&list, REACH, p, radius);
            *o = kernel_of(p, &hood, settings);
        });
        crate::cancel::advance(out.len() as u64)?;
    }
    for (&i, (c, s)) in list.order.iter().zip(sorted_out) {
        centres[i as usize] = c;
        forms[i as usize] = s;
    }
    Ok((centres, forms))
}

/// A particle's neighbourhood: the weights' sum, the weighted sums of the offsets and of their
/// outer products, and the neighbours other than itself.
struct Neighbourhood {
    weight: f64,
    first: DVec3,
    second: [f64; 6],
    count: usize,
}

/// The sums of [`Neighbourhood`] over the particles within `radius` of `p` (offsets from `p`).
fn neighbourhood(list: &CellList, reach: usize, p: DVec3, radius: f64) -> Neighbourhood {
    let inv = 1.0 / radius;
    let r2 = radius * radius;
    let mut h = Neighbourhood {
        weight: 0.0,
        first: DVec3::ZERO,
        second: [0.0; 6],
        count: 0,
    };
    list.runs_within(p, reach, |run| {
        for &c in run {
            let d = c - p;
            let d2 = d.length_squared();
            if d2 >= r2 {
                continue;
            }
            let q = d2.sqrt() * inv;
            let w = 1.0 - q * q * q;
            h.weight += w;
            h.first += d * w;
            let [s0, s1, s2, s3, s4, s5] = &mut h.second;
            *s0 += w * d.x * d.x;
            *s1 += w * d.x * d.y;
            *s2 += w * d.x * d.z;
            *s3 += w * d.y * d.y;
            *s4 += w * d.y * d.z;
            *s5 += w * d.z * d.z;
            h.count += 1;
        }
    });
    // The particle itself is among the runs (at distance 0).
    h.count = h.count.saturating_sub(1);
    h
}

/// The centre and the shape of the kernel of the particle at `p` with neighbourhood `h`.
fn kernel_of(p: DVec3, h: &Neighbourhood, s: &AnisotropySettings) -> (DVec3, [f64; 9]) {
    let mean = h.first / h.weight;
    let centre = p + mean * s.smoothing;
    if h.count < s.min_neighbours {
        let k = 1.0 / s.k_n;
        return (centre, [k, 0.0, 0.0, 0.0, k, 0.0, 0.0, 0.0, k]);
    }
    let [s0, s1, s2, s3, s4, s5] = h.second.map(|v| v / h.weight);
    let c = [
        [
            s0 - mean.x * mean.x,
            s1 - mean.x * mean.y,
            s2 - mean.x * mean.z,
        ],
        [
            s1 - mean.x * mean.y,
            s3 - mean.y * mean.y,
            s4 - mean.y * mean.z,
        ],
        [
            s2 - mean.x * mean.z,
            s4 - mean.y * mean.z,
            s5 - mean.z * mean.z,
        ],
    ];
    let (values, v) = symmetric_eigen(c);
    let largest = values.iter().fold(0.0f64, |m, &x| m.max(x));
    if largest <= 0.0 || largest.is_nan() {
        let k = 1.0 / s.k_n;
        return (centre, [k, 0.0, 0.0, 0.0, k, 0.0, 0.0, 0.0, k]);
    }
    // 1/Σ̃ per eigenvector.
    let inverse = values.map(|x| largest / (s.k_s * x.max(largest / s.k_r)));
    let mut shape = [0.0; 9];
    for a in 0..3 {
        for b in 0..3 {
            shape[3 * a + b] = (0..3).map(|m| v[a][m] * inverse[m] * v[b][m]).sum();
        }
    }
    (centre, shape)
}

/// The determinant of a row-major 3×3 matrix.
pub fn determinant(m: &[f64; 9]) -> f64 {
    m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
        + m[2] * (m[3] * m[7] - m[4] * m[6])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lattice(nx: usize, ny: usize, nz: usize, s: f64) -> Vec<DVec3> {
        let mut p = Vec::new();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    p.push(DVec3::new(i as f64, j as f64, k as f64) * s);
                }
            }
        }
        p
    }

    /// Inside a block the kernels are about round, on its top face flattened along z, and a
    /// lone particle's is round of radius k_n·H.
    #[test]
    fn shapes_follow_the_neighbourhood() {
        let mut p = lattice(16, 16, 8, 1.0);
        p.push(DVec3::new(100.0, 0.0, 0.0));
        let h = 2.0;
        let s = AnisotropySettings::default();
        let (centres, shapes) = shapes(&p, h, &s).unwrap();
        let inner = 8 + 16 * (8 + 16 * 4);
        let (values, _) = symmetric_eigen(to_rows(&shapes[inner]));
        for v in values {
            assert!((0.7..1.4).contains(&v), "{values:?}");
        }
        let top = 8 + 16 * (8 + 16 * 7);
        let m = to_rows(&shapes[top]);
        // Squashed along z: S's zz entry (1/Σ̃) the largest, up to k_r times the others'.
        assert!(m[2][2] > 2.5 * m[0][0] && m[2][2] > 2.5 * m[1][1], "{m:?}");
        assert!(centres[top].z < p[top].z);
        let lone = shapes.last().unwrap();
        assert_eq!(*lone, [2.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 2.0]);
        assert_eq!(*centres.last().unwrap(), DVec3::new(100.0, 0.0, 0.0));
    }

    fn to_rows(m: &[f64; 9]) -> [[f64; 3]; 3] {
        [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]]
    }

    #[test]
    fn bad_settings_named() {
        for (s, name) in [
            (
                AnisotropySettings {
                    k_r: -1.0,
                    ..Default::default()
                },
                "k_r",
            ),
            (
                AnisotropySettings {
                    k_s: 0.0,
                    ..Default::default()
                },
                "k_s",
            ),
            (
                AnisotropySettings {
                    smoothing: 1.5,
                    ..Default::default()
                },
                "smoothing",
            ),
        ] {
            let e = shapes(&[DVec3::ZERO], 1.0, &s).unwrap_err();
            assert!(
                matches!(e, Error::InvalidArgument { name: n, .. } if n == name),
                "{e}"
            );
        }
    }
}
