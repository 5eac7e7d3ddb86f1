//! Times the polygonizers on random blob fields (the benchmark cases), for profiling:
//! `cargo bench --bench blob_timing -- 200 0.25 128 dense [repeats] [voxel_size]`
//! (method `dense`, `sparse`, `tracking` or `blocks` (the `Tessellator`'s walk block by block); prints the phases of the last run and the median).
use glam::DVec3;
use implicitmesh::field::blob::{BlobField, BlobSettings, PerPrimitive};
use implicitmesh::lattice::Lattice;
use implicitmesh::polygonize::tracking::{Components, TrackingSettings};
use implicitmesh::polygonize::{polygonize, tracking, Method, Polygonized, Settings};
use std::time::Instant;

fn main() {
    let a: Vec<String> = std::env::args().filter(|s| s != "--bench").collect();
    let n: usize = a.get(1).map_or(200, |s| s.parse().unwrap());
    let r: f64 = a.get(2).map_or(0.25, |s| s.parse().unwrap());
    let res: u32 = a.get(3).map_or(128, |s| s.parse().unwrap());
    let method = a.get(4).map_or("dense", |s| s.as_str());
    let reps: usize = a.get(5).map_or(20, |s| s.parse().unwrap());
    let voxel_size: f64 = a
        .get(6)
        .map_or(BlobSettings::default().voxel_size, |s| s.parse().unwrap());
    // A small deterministic generator (splitmix64).
    let mut state = 12345u64;
    let mut next = || {
        state = state.wrapping_add(0x9e3779b97f4a7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d049bb133111eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let centers: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(next(), next(), next()) * 1.6 - 0.8)
        .collect();
    let field = BlobField::new(
        &centers,
        PerPrimitive::All(r),
        PerPrimitive::All(1.0),
        0.5,
        BlobSettings {
            voxel_size,
            ..Default::default()
        },
    )
    .unwrap();
    let g = field.grid();
    let nvox: u32 = g.dims().iter().product();
    println!(
        "voxel size {voxel_size}: {:?} voxels, {:.1} entries per voxel",
        g.dims(),
        g.entries() as f64 / nvox as f64
    );
    let lattice = Lattice::new(DVec3::splat(-1.0), DVec3::splat(1.0), [res; 3]).unwrap();
    let settings = Settings::default();
    let mut tess = tracking::Tessellator::new();
    // Every component, the walks from the centres going up to the lattice's side.
    let tracking_settings = TrackingSettings {
        starts: centers.clone(),
        max_walk: res,
        components: Components::All,
        ..Default::default()
    };
    let mut times = vec![];
    // Fastest time of each phase over the runs.
    let mut phases: Vec<(&'static str, f64)> = Vec::new();
    for _ in 0..reps {
        let t = Instant::now();
        let (tris, stats) = match method {
            "tracking" => {
                let (m, s) = tess
                    .polygonize(&field, &lattice, &tracking_settings)
                    .unwrap();
                (m.triangles.len(), s)
            }
            "blocks" => {
                let (_, t, s) = tess
                    .polygonize_blocks::<_, u32>(&field, &lattice, &tracking_settings)
                    .unwrap();
                (t.len(), s)
            }
            "sparse" => {
                let Polygonized {
                    mesh: m, stats: s, ..
                } = polygonize(&field, &lattice, &Method::Sparse(settings)).unwrap();
                (m.triangles.len(), s)
            }
            _ => {
                let Polygonized {
                    mesh: m, stats: s, ..
                } = polygonize(&field, &lattice, &Method::Dense(settings)).unwrap();
                (m.triangles.len(), s)
            }
        };
        times.push(t.elapsed().as_secs_f64());
        for &(name, secs) in &stats.seconds {
            match phases.iter_mut().find(|p| p.0 == name) {
                Some(p) => p.1 = p.1.min(secs),
                None => phases.push((name, secs)),
            }
        }
        if times.len() == reps {
            println!(
                "{tris} triangles, {} evaluations, {:?}",
                stats.evaluations, stats.seconds
            );
        }
    }
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!(
        "{method} {n} blobs r={r} {res}³: median {:.2} ms, min {:.2} ms",
        times[reps / 2] * 1e3,
        times[0] * 1e3
    );
    let fastest: Vec<String> = phases
        .iter()
        .map(|(name, s)| format!("{name} {:.2} ms", s * 1e3))
        .collect();
    println!("fastest phases: {}", fastest.join(", "));
}
