//! The SPH colour field of a set of particles, as splashsurf builds it: with per-particle
//! densities ρᵢ = Σⱼ m W(|xᵢ − xⱼ|, H) (the particle itself included), the level set
//! Σᵢ (m/ρᵢ) W(|x − xᵢ|, H) = threshold, a blob field with one primitive of support H per particle.
//!
//! splashsurf's parameters: particle radius r, `smoothing_length` ℓ relative to r (compact
//! support H = 2ℓr, as pysplashsurf reads it), the cubic spline kernel, `iso_surface_threshold`
//! (0.6). Its particle mass m = ρ₀(2r)³ and rest density ρ₀ cancel: with W = σ/H³ · w (w the
//! profile of [`BlobKernel`], 1 at the centre), (m/ρᵢ) W(d, H) = w(d/H) / Σⱼ w(|xᵢ − xⱼ|/H), so
//! the strength of particle i is Aᵢ = 1 / Σⱼ w(|xᵢ − xⱼ|/H) and neither m, ρ₀ nor σ appears.

use crate::error::{check_finite_points, Error, Result};
use crate::field::blob::anisotropy::{self, AnisotropySettings};
use crate::field::blob::densities::kernel_sums;
use crate::field::blob::kernel::BlobKernel;
use crate::field::blob::{BlobField, BlobSettings, PerPrimitive, Precision};
use glam::DVec3;

/// Options of [`colour_field`] (splashsurf's names and defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParticleSettings {
    /// The smoothing length relative to the particle radius r; the kernel's compact support is
    /// H = 2 · smoothing_length · r (as pysplashsurf reads it). Default 2.0 (H = 4r, twice the
    /// particle spacing 2r).
    pub smoothing_length: f64,
    /// The colour field's value on the surface. Default 0.6.
    pub iso_surface_threshold: f64,
    /// The SPH kernel W. Default the cubic spline (splashsurf's).
    pub kernel: BlobKernel,
    /// Voxel side of the field's grid as a multiple of H (see [`BlobSettings::voxel_size`]).
    pub voxel_size: f64,
    /// The field's precision ([`BlobSettings::precision`]); the densities are computed in f64
    /// whichever it is.
    pub precision: Precision,
    /// Anisotropic kernels (Yu & Turk, [`crate::field::blob::anisotropy`]) when set: each
    /// particle's kernel stretched along its neighbourhood's principal axes, its strength
    /// times det Sᵢ, its centre smoothed. Default None (round kernels, splashsurf's field).
    pub anisotropy: Option<AnisotropySettings>,
}

impl Default for ParticleSettings {
    fn default() -> Self {
        ParticleSettings {
            smoothing_length: 2.0,
            iso_surface_threshold: 0.6,
            kernel: BlobKernel::CubicSpline,
            voxel_size: BlobSettings::default().voxel_size,
            precision: Precision::Double,
            anisotropy: None,
        }
    }
}

/// The colour field of `particles` of radius `particle_radius` (see the module docs). The
/// densities are computed in parallel over a cell list ([`kernel_sums`]); the call stops between
/// steps when its [`crate::cancel`] token is set, and reports particles done.
pub fn colour_field(
    particles: &[DVec3],
    particle_radius: f64,
    settings: &ParticleSettings,
) -> Result<BlobField> {
    check_finite_points("particles", particles)?;
    crate::spatial::check_far("particles", particles)?;
    let support = compact_support(particle_radius, settings)?;
    if let Some(a) = &settings.anisotropy {
        a.check()?;
    }
    let blob = BlobSettings {
        voxel_size: settings.voxel_size,
        kernel: settings.kernel,
        precision: Precision::Double,
    };
    let sums = kernel_sums(particles, support, settings.kernel)?;
    let mut strengths: Vec<f64> = sums.iter().map(|s| 1.0 / s).collect();
    let threshold = settings.iso_surface_threshold;
    let mut field = match &settings.anisotropy {
        None => BlobField::new(
            particles,
            PerPrimitive::All(support),
            PerPrimitive::Each(&strengths),
            threshold,
            blob,
        )?,
        Some(a) => {
            let (centres, shapes) = anisotropy::shapes(particles, support, a)?;
            for (s, m) in strengths.iter_mut().zip(&shapes) {
                *s *= anisotropy::determinant(m);
            }
            BlobField::with_shapes(
                &centres,
                PerPrimitive::All(support),
                PerPrimitive::Each(&strengths),
                threshold,
                blob,
                &shapes,
            )?
        }
    };
    field.set_precision(settings.precision);
    Ok(field)
}

/// H = 2 · smoothing_length · particle_radius, with these and the threshold checked positive
/// and finite.
fn compact_support(particle_radius: f64, settings: &ParticleSettings) -> Result<f64> {
    let smoothing_length = settings.smoothing_length;
    for (name, v) in [
        ("particle_radius", particle_radius),
        ("smoothing_length", smoothing_length),
        ("iso_surface_threshold", settings.iso_surface_threshold),
        ("voxel_size", settings.voxel_size),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(
                name,
                format!("must be positive and finite, got {v}"),
            ));
        }
    }
    let support = 2.0 * smoothing_length * particle_radius;
    crate::field::blob::densities::check_support("particle_radius", support)?;
    Ok(support)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    /// The colour field against the formula summed directly with splashsurf's normalised kernel
    /// and mass.
    #[test]
    fn equals_the_direct_sum() {
        let (r, ell) = (0.05, 2.0);
        let p = random_points(300, -0.4, 0.4, 3);
        let s = ParticleSettings::default();
        let f = colour_field(&p, r, &s).unwrap();
        let h = 2.0 * ell * r;
        let sigma = 8.0 / (std::f64::consts::PI * h * h * h);
        let w = |d: f64| sigma * BlobKernel::CubicSpline.value(d, h);
        let mass = 1000.0 * (2.0 * r).powi(3);
        let rho: Vec<f64> = p
            .iter()
            .map(|a| mass * p.iter().map(|b| w((*a - *b).length())).sum::<f64>())
            .collect();
        for x in random_points(500, -0.6, 0.6, 4) {
            let want: f64 = p
                .iter()
                .zip(&rho)
                .map(|(c, rho)| mass / rho * w((x - *c).length()))
                .sum();
            assert!((f.potential(x) - want).abs() < 1e-12, "{x}");
        }
    }

    /// Inside a block of particles on a lattice of spacing 2r the colour field is about 1.
    #[test]
    fn about_one_inside_a_uniform_block() {
        let r = 0.5;
        let p: Vec<DVec3> = (0..12 * 12 * 12)
            .map(|i| DVec3::new((i % 12) as f64, (i / 12 % 12) as f64, (i / 144) as f64))
            .collect();
        for kernel in [BlobKernel::CubicSpline, BlobKernel::Wendland] {
            let s = ParticleSettings {
                kernel,
                ..Default::default()
            };
            let f = colour_field(&p, r, &s).unwrap();
            // At a particle, exactly 1: every particle within reach has the same strength.
            assert!((f.potential(DVec3::splat(5.0)) - 1.0).abs() < 1e-12);
            for x in [DVec3::splat(5.5), DVec3::new(5.0, 6.25, 5.5)] {
                assert!(
                    (f.potential(x) - 1.0).abs() < 0.06,
                    "{kernel:?}: {}",
                    f.potential(x)
                );
            }
        }
    }

    #[test]
    fn bad_input_named() {
        let p = [DVec3::ZERO];
        let s = ParticleSettings::default();
        for (r, ell, name) in [
            (0.0, 2.0, "particle_radius"),
            (0.1, f64::NAN, "smoothing_length"),
        ] {
            let s = ParticleSettings {
                smoothing_length: ell,
                ..s
            };
            let e = colour_field(&p, r, &s).unwrap_err();
            assert!(
                matches!(e, Error::InvalidArgument { name: n, .. } if n == name),
                "{e}"
            );
        }
        let e = colour_field(&[DVec3::NAN], 0.1, &s).unwrap_err();
        assert!(
            matches!(
                e,
                Error::NotFinite {
                    name: "particles",
                    ..
                }
            ),
            "{e}"
        );
    }
}
