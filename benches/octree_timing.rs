//! Times the octree polygonizer against dense marching cubes on a variational surface fitted to
//! a PLY mesh, in paired rounds (octree, then dense), for profiling:
//! `cargo bench --bench octree_timing -- path/to/mesh.ply [resolution] [rounds] [octree]`
//! (over [-1, 1]³, d = 0.015 as in the benchmark; prints the octree's phases of its fastest run;
//! `octree` skips dense, for profiles of the octree alone).
use glam::DVec3;
use implicitmesh::field::rbf::constraints;
use implicitmesh::field::rbf::{FitSettings, VariationalSurface};
use implicitmesh::lattice::Lattice;
use implicitmesh::polygonize::{octree, polygonize, Method, Polygonized, Settings};
use std::time::Instant;

#[path = "common/ply.rs"]
mod ply;
use ply::read_ply;

fn main() {
    let a: Vec<String> = std::env::args().filter(|s| s != "--bench").collect();
    let path = a.get(1).expect("mesh path");
    let res: u32 = a.get(2).map_or(128, |s| s.parse().unwrap());
    let rounds: usize = a.get(3).map_or(7, |s| s.parse().unwrap());
    let alone = a.get(4).is_some_and(|s| s == "octree");
    let (v, f) = read_ply(path);
    let placement = constraints::ConstraintSettings {
        d: Some(0.015),
        ..Default::default()
    };
    let s = VariationalSurface::from_mesh(&v, &f, &placement, &FitSettings::default()).unwrap();
    let lattice = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [res; 3]).unwrap();
    let set = Settings::default();
    let oct = octree::OctreeSettings {
        common: set,
        ..Default::default()
    };
    let (mut ratios, mut best) = (Vec::new(), None::<(f64, _)>);
    for _ in 0..rounds {
        let t = Instant::now();
        let Polygonized {
            mesh: m, stats: st, ..
        } = polygonize(&s, &lattice, &Method::Octree(oct)).unwrap();
        let to = t.elapsed().as_secs_f64();
        if !alone {
            let t = Instant::now();
            let d = polygonize(&s, &lattice, &Method::Dense(set)).unwrap().mesh;
            let td = t.elapsed().as_secs_f64();
            assert_eq!(m.triangles.len(), d.triangles.len());
            ratios.push(td / to);
        }
        if best.as_ref().is_none_or(|b| to < b.0) {
            best = Some((to, st));
        }
    }
    ratios.sort_by(f64::total_cmp);
    if ratios.is_empty() {
        ratios.push(f64::NAN);
    }
    let (to, st) = best.unwrap();
    println!(
        "octree {:.4} s (fastest), {} evaluations ({:.2} %); dense / octree paired median {:.2} ({:.2}-{:.2})",
        to,
        st.evaluations,
        st.evaluation_percent(),
        ratios[ratios.len() / 2],
        ratios[0],
        ratios[ratios.len() - 1]
    );
    for (phase, secs) in &st.seconds {
        println!("  {phase}: {secs:.4}");
    }
}
