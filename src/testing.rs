//! What the crate's tests share: the pseudo-random numbers they draw ([`XorShift`], and
//! [`Lcg`] where a test's cases were drawn with it), point sets (random points, a sphere, a
//! thin box with its normals) and random blob fields, reference checks (gradients against
//! differences, order-free mesh comparison) and a field whose block bounds lie. Every generator
//! is deterministic, so each test sees the same cases on every run and machine.

use crate::field::{Block, BlockField, BlockSign, DynBlockField, Field};
use crate::lattice::Lattice;
use glam::DVec3;

/// Marsaglia's xorshift64 generator (shifts 13, 7, 17): each draw steps the state and returns
/// it. The state must not be 0 (it would stay 0).
pub struct XorShift(u64);

impl XorShift {
    /// The generator from state `seed` (not 0).
    pub fn new(seed: u64) -> XorShift {
        debug_assert_ne!(seed, 0, "a xorshift state of 0 stays 0");
        XorShift(seed)
    }

    /// The next 64 bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.0 = x;
        x
    }

    /// The next number in [0, 1) (the top 53 bits of [`XorShift::next_u64`]).
    pub fn uniform(&mut self) -> f64 {
        unit(self.next_u64())
    }
}

/// Knuth's 64-bit linear congruential generator (MMIX multiplier and increment): each draw
/// steps the state and returns it.
pub struct Lcg(u64);

impl Lcg {
    /// The generator from state `seed`.
    pub fn new(seed: u64) -> Lcg {
        Lcg(seed)
    }

    /// The next number in [0, 1) (the top 53 bits of the state).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        unit(self.0)
    }
}

/// The number in [0, 1) of the top 53 bits of `bits`.
fn unit(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

/// `n` evenly spread unit vectors (a Fibonacci sphere, the pole along z).
pub fn fibonacci_sphere(n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = golden * i as f64;
            DVec3::new(r * a.cos(), r * a.sin(), z)
        })
        .collect()
}

/// The box [0, 1]² × [0, t] sampled on grids of spacing about `h`, with outward normals.
pub fn thin_box(h: f64, t: f64) -> (Vec<DVec3>, Vec<DVec3>) {
    let m = (1.0 / h).round() as usize;
    let layers = ((t / h).ceil() as usize).max(1);
    let (mut p, mut n) = (Vec::new(), Vec::new());
    for i in 0..=m {
        for j in 0..=m {
            let (x, y) = (i as f64 / m as f64, j as f64 / m as f64);
            p.push(DVec3::new(x, y, 0.0));
            n.push(-DVec3::Z);
            p.push(DVec3::new(x, y, t));
            n.push(DVec3::Z);
        }
    }
    for i in 0..m {
        for l in 1..layers {
            let (u, z) = (i as f64 / m as f64, t * l as f64 / layers as f64);
            for (q, d) in [
                (DVec3::new(u, 0.0, z), -DVec3::Y),
                (DVec3::new(1.0, u, z), DVec3::X),
                (DVec3::new(1.0 - u, 1.0, z), DVec3::Y),
                (DVec3::new(0.0, 1.0 - u, z), -DVec3::X),
            ] {
                p.push(q);
                n.push(d);
            }
        }
    }
    (p, n)
}

/// Largest relative difference between a field's analytic gradient and central differences
/// at the given points.
pub fn gradient_error<F: Field>(field: &F, points: &[DVec3], h: f64) -> f64 {
    let mut worst: f64 = 0.0;
    for &p in points {
        let g = field.gradient(p);
        let d = |e: DVec3| (field.value(p + e * h) - field.value(p - e * h)) / (2.0 * h);
        let fd = DVec3::new(d(DVec3::X), d(DVec3::Y), d(DVec3::Z));
        let err = (g - fd).length() / g.length().max(1.0);
        worst = worst.max(err);
    }
    worst
}

/// A blob field whose block bounds wrongly rule out every block with bx = 2 (for the
/// errors of polygonizers that trust them).
pub struct Lying(pub crate::field::blob::BlobField);

impl Lying {
    /// One blob of radius 0.9 at the origin: its surface (a sphere of radius 0.487) crosses
    /// blocks with bx = 2 on a 32³ lattice over [-1, 1]³.
    pub fn sphere() -> Lying {
        use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
        let one = |r| PerPrimitive::All(r);
        let blob = BlobField::new(
            &[DVec3::ZERO],
            one(0.9),
            one(1.0),
            0.5,
            BlobSettings::default(),
        );
        Lying(blob.unwrap())
    }
}

/// Triangles as sorted triples of vertex bit patterns, each rotated so that its smallest
/// vertex comes first (keeping its orientation): order-free and bit-exact.
pub fn canonical_triangles(vertices: &[DVec3], triangles: &[[u32; 3]]) -> Vec<[[u64; 3]; 3]> {
    let key = |v: u32| vertices[v as usize].to_array().map(f64::to_bits);
    let mut t: Vec<[[u64; 3]; 3]> = triangles
        .iter()
        .map(|t| {
            let k = t.map(key);
            let s = (0..3).min_by_key(|&i| k[i]).unwrap();
            [k[s], k[(s + 1) % 3], k[(s + 2) % 3]]
        })
        .collect();
    t.sort_unstable();
    t
}

/// (vertex, normal) bit patterns, sorted: order-free and bit-exact.
pub fn vertex_normal_bits(vertices: &[DVec3], normals: &[DVec3]) -> Vec<([u64; 3], [u64; 3])> {
    let mut p: Vec<_> = vertices
        .iter()
        .zip(normals)
        .map(|(v, n)| {
            (
                v.to_array().map(f64::to_bits),
                n.to_array().map(f64::to_bits),
            )
        })
        .collect();
    p.sort_unstable();
    p
}

impl Field for Lying {
    fn value(&self, p: DVec3) -> f64 {
        self.0.value(p)
    }
    fn block_field(&self) -> Option<&dyn DynBlockField> {
        Some(self)
    }
}

impl BlockField for Lying {
    type Blocks = <crate::field::blob::BlobField as BlockField>::Blocks;
    fn blocks(&self, lattice: &Lattice, blocks: [u32; 3]) -> Self::Blocks {
        self.0.blocks(lattice, blocks)
    }
    fn block_sign(&self, blocks: &Self::Blocks, lattice: &Lattice, block: &Block) -> BlockSign {
        if block.index[0] == 2 {
            return BlockSign::Outside;
        }
        self.0.block_sign(blocks, lattice, block)
    }
    fn block_values(
        &self,
        blocks: &Self::Blocks,
        lattice: &Lattice,
        block: &Block,
        out: &mut [f64; 512],
    ) -> BlockSign {
        if block.index[0] == 2 {
            return BlockSign::Outside;
        }
        self.0.block_values(blocks, lattice, block, out)
    }
}

/// `n` blobs of radius `r` (strength 1, threshold 0.5) at random centres in [-0.8, 0.8]³.
pub fn random_blobs(n: usize, r: f64, seed: u64) -> crate::field::blob::BlobField {
    use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
    let c = random_points(n, -0.8, 0.8, seed);
    BlobField::new(
        &c,
        PerPrimitive::All(r),
        PerPrimitive::All(1.0),
        0.5,
        BlobSettings::default(),
    )
    .unwrap()
}

/// `n` blobs summing `kernel`, of radii in [0.1, 0.3] (strength 1, threshold 0.5), at random
/// centres in [-0.8, 0.8]³ ([`random_points`] of `seed`; the radii of `seed + 1`).
pub fn sized_blobs(
    n: usize,
    seed: u64,
    kernel: crate::field::blob::kernel::BlobKernel,
) -> crate::field::blob::BlobField {
    use crate::field::blob::{BlobField, BlobSettings, PerPrimitive};
    let c = random_points(n, -0.8, 0.8, seed);
    let r: Vec<f64> = random_points(n, 0.1, 0.3, seed + 1)
        .iter()
        .map(|p| p.x)
        .collect();
    BlobField::new(
        &c,
        PerPrimitive::Each(&r),
        PerPrimitive::All(1.0),
        0.5,
        BlobSettings {
            kernel,
            ..Default::default()
        },
    )
    .unwrap()
}

/// Random blob clusters to polygonize, as (blobs, radius, cells per axis over [-1, 1]³,
/// seed): from one blob at 7³ cells to 500 small ones, on lattices cut in partial blocks.
pub const BLOB_CASES: [(usize, f64, u32, u64); 6] = [
    (200, 0.25, 64, 1),
    (60, 0.12, 37, 2),
    (500, 0.08, 50, 3),
    (5, 0.6, 22, 4),
    (1, 0.3, 7, 5),
    (30, 0.2, 8, 6),
];

/// Calls `f` with the field ([`random_blobs`]) and the lattice (cubic over [-1, 1]³) of
/// each of `cases` (as in [`BLOB_CASES`]).
pub fn for_each_blob_case(
    cases: &[(usize, f64, u32, u64)],
    mut f: impl FnMut(crate::field::blob::BlobField, &crate::lattice::Lattice),
) {
    for &(n, r, res, seed) in cases {
        let lo = DVec3::splat(-1.0);
        let l = crate::lattice::Lattice::cubic(lo, -lo, res).unwrap();
        f(random_blobs(n, r, seed), &l);
    }
}

/// A cube of `side`³ particles on a lattice of spacing 1 from the origin, each moved by up
/// to ±0.1 per axis ([`random_points`] of `seed`).
pub fn jittered_cube(side: u32, seed: u64) -> Vec<DVec3> {
    let jitter = random_points(side.pow(3) as usize, -0.1, 0.1, seed);
    let s = side as usize;
    let grid = |i: usize| DVec3::new((i % s) as f64, (i / s % s) as f64, (i / s / s) as f64);
    jitter
        .iter()
        .enumerate()
        .map(|(i, d)| grid(i) + *d)
        .collect()
}

/// Deterministic pseudo-random points in a box ([`XorShift`] of `seed`, or of 1 for 0).
pub fn random_points(n: usize, lo: f64, hi: f64, seed: u64) -> Vec<DVec3> {
    let mut rng = XorShift::new(seed.max(1));
    let mut next = move || rng.uniform();
    (0..n)
        .map(|_| {
            DVec3::new(
                lo + (hi - lo) * next(),
                lo + (hi - lo) * next(),
                lo + (hi - lo) * next(),
            )
        })
        .collect()
}
