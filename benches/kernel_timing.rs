//! Times the radial-basis kernel sums on one thread, for tuning the vector paths:
//! `cargo bench --bench kernel_timing -- [centres] [blocks] [rounds]`
//! (prints nanoseconds per point-centre pair for values, values with gradients, and gradients).
use implicitmesh::field::rbf::kernel::{
    block_gradients, block_values, block_values_gradients, Block, Centres, Triharmonic, LANES,
};
use std::time::Instant;

fn main() {
    let a: Vec<String> = std::env::args().filter(|s| s != "--bench").collect();
    let n: usize = a.get(1).map_or(1600, |s| s.parse().unwrap());
    let nb: usize = a.get(2).map_or(2048, |s| s.parse().unwrap());
    let rounds: usize = a.get(3).map_or(7, |s| s.parse().unwrap());
    let mut seed = 12345u64;
    let mut rnd = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let mut c = Centres::default();
    for _ in 0..n {
        c.x.push(rnd());
        c.y.push(rnd());
        c.z.push(rnd());
        c.w.push(rnd());
    }
    let blocks: Vec<Block> = (0..nb)
        .map(|_| {
            let mut b = Block::default();
            for l in 0..LANES {
                b.x[l] = rnd();
                b.y[l] = rnd();
                b.z[l] = rnd();
            }
            b
        })
        .collect();
    let pairs = (n * nb * LANES) as f64;
    let time = |f: &mut dyn FnMut()| {
        let mut best = f64::INFINITY;
        for _ in 0..rounds {
            let t = Instant::now();
            f();
            best = best.min(t.elapsed().as_secs_f64());
        }
        best / pairs * 1e9
    };
    let mut v = vec![[0.0; LANES]; nb];
    let mut g = vec![[[0.0; LANES]; 4]; nb];
    let tv = time(&mut || block_values::<Triharmonic>(&c, &blocks, &mut v));
    let tvg = time(&mut || block_values_gradients::<Triharmonic>(&c, &blocks, &mut g));
    let tg = time(&mut || block_gradients::<Triharmonic>(&c, &blocks, &mut g));
    println!("ns per pair: values {tv:.4}, values+gradients {tvg:.4}, gradients {tg:.4}");
    println!("checksum {}", v[0][0] + g[0][1][0]);
}
