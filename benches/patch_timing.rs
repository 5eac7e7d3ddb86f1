//! Times the stages of one partition-of-unity patch's fit on a cap of a sphere with offset
//! points, as a partition fit's patches are: the factorization (assembly, null-space
//! projection, Cholesky), one solve, one residual evaluation, and the Cholesky factorization
//! alone at the same order: `cargo bench --bench patch_timing`.
use faer::Par;
use glam::DVec3;
use implicitmesh::field::rbf::kernel::{values_by_point, Arithmetic, Centres, Triharmonic};
use implicitmesh::linalg::saddle::SaddleSolver;
use std::time::Instant;

fn cap(m: usize, seed: u64) -> (Vec<DVec3>, Vec<f64>) {
    let mut s = seed;
    let mut r = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut pts = Vec::new();
    let mut vals = Vec::new();
    while pts.len() < m {
        let (u, v) = (r() * 0.3, r() * std::f64::consts::TAU);
        let n = DVec3::new(u.sin() * v.cos(), u.sin() * v.sin(), u.cos());
        pts.push(n);
        vals.push(0.0);
        if pts.len() < m && r() < 0.5 {
            pts.push(n * 1.01);
            vals.push(0.01);
        }
    }
    (pts, vals)
}

fn main() {
    for &m in &[64usize, 96, 128, 192] {
        let reps = 2000;
        let sets: Vec<_> = (0..16).map(|k| cap(m, 7 + k)).collect();
        let (mut ta, mut ts, mut tr) = (0.0, 0.0, 0.0);
        for k in 0..reps {
            let (p, v) = &sets[k % sets.len()];
            let t = Instant::now();
            let solver = SaddleSolver::with_parallelism(
                p,
                Arithmetic::<Triharmonic>::default(),
                0.0,
                1.0,
                Par::Seq,
            )
            .unwrap();
            ta += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let (lam, _a) = solver.solve(v, [0.0; 4]);
            ts += t.elapsed().as_secs_f64();
            let c = Centres {
                x: p.iter().map(|q| q.x).collect(),
                y: p.iter().map(|q| q.y).collect(),
                z: p.iter().map(|q| q.z).collect(),
                w: lam,
            };
            let q: Vec<[f64; 3]> = p.iter().map(|q| q.to_array()).collect();
            let mut out = vec![0.0; m];
            let t = Instant::now();
            values_by_point::<Triharmonic>(&c, &q, &mut out);
            tr += t.elapsed().as_secs_f64();
        }
        // The factorization alone, on an SPD matrix of the same order.
        let mm = m - 4;
        let b: Vec<f64> = (0..mm * mm)
            .map(|k| ((k * 7919) % 101) as f64 / 101.0 - 0.5)
            .collect();
        let mut spd = vec![0.0; mm * mm];
        for i in 0..mm {
            for j in 0..mm {
                spd[i + j * mm] = (0..mm).map(|k| b[i + k * mm] * b[j + k * mm]).sum::<f64>()
                    + if i == j { mm as f64 } else { 0.0 };
            }
        }
        let mut tc = 0.0;
        let mut work = spd.clone();
        for _ in 0..reps {
            work.copy_from_slice(&spd);
            let t = Instant::now();
            let ok = implicitmesh::linalg::cholesky::factor_lower(
                faer::MatMut::from_column_major_slice_mut(&mut work, mm, mm),
            );
            tc += t.elapsed().as_secs_f64();
            assert_eq!(ok, Some(true));
        }
        println!("m {m}: cholesky alone {:.1} us", tc / reps as f64 * 1e6);
        let us = |x: f64| x / reps as f64 * 1e6;
        println!(
            "m {m}: factor {:.1} us, solve {:.1} us, residual {:.1} us (cholesky flops {:.1} k)",
            us(ta),
            us(ts),
            us(tr),
            (m as f64).powi(3) / 3.0 / 1e3
        );
    }
}
