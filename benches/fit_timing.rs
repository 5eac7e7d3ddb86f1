//! Times the phases of a variational fit and of batched evaluation on a PLY mesh:
//! `cargo bench --bench fit_timing -- path/to/mesh.ply`.
use glam::DVec3;
use implicitmesh::field::rbf::{FitSettings, VariationalSurface};
use implicitmesh::field::Field;
use std::time::Instant;

#[path = "common/ply.rs"]
mod ply;
use ply::read_ply;

fn main() {
    let path = std::env::args()
        .filter(|s| s != "--bench")
        .nth(1)
        .expect("mesh path");
    let (v, f) = read_ply(&path);
    for _ in 0..3 {
        let t = Instant::now();
        let s = VariationalSurface::from_mesh(&v, &f, &Default::default(), &FitSettings::default())
            .unwrap();
        println!(
            "fit {} centres: {:.4} s (residual {:.2e})",
            s.centers().len(),
            t.elapsed().as_secs_f64(),
            s.residual()
        );
    }
    let s = VariationalSurface::from_mesh(&v, &f, &Default::default(), &FitSettings::default())
        .unwrap();
    let n = 1_000_000;
    let mut state = 12345u64;
    let pts: Vec<DVec3> = (0..n)
        .map(|_| {
            let mut r = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            };
            DVec3::new(r(), r(), r())
        })
        .collect();
    let mut out = vec![0.0; n];
    for _ in 0..3 {
        let t = Instant::now();
        s.values(&pts, &mut out);
        let secs = t.elapsed().as_secs_f64();
        println!(
            "evaluate 1e6 points: {:.4} s = {:.2} G kernel/s",
            secs,
            1e6 * s.centers().len() as f64 / secs / 1e9
        );
    }
}
