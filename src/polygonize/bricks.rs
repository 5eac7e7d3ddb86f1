//! Block-sparse, time-stamped storage for the tracking polygonizer's caches (Triquet et al.
//! §4.1 and §4.7): the lattice is split into bricks of 8 × 8 × 8 lattice points; a small dense
//! table maps each brick position to a brick of the pool, handed out on first touch in a call.
//! Every entry carries the stamp of the call that wrote it, so entries from earlier calls are
//! simply stale: nothing is cleared between calls, bricks are recycled from call to call, and
//! memory grows with the number of bricks the surface touches, not with the lattice.

/// Lattice points per brick side.
pub const SIDE: u32 = 8;
const LOCAL: usize = (SIDE * SIDE * SIDE) as usize;
const NONE: u32 = u32::MAX;

/// One brick: per lattice point a value, per lattice edge (3 axes) a vertex index, per cell a
/// "queued" mark, each with its stamp.
#[derive(Clone)]
struct Brick {
    value: [f64; LOCAL],
    value_stamp: [u32; LOCAL],
    edge: [u32; 3 * LOCAL],
    edge_stamp: [u32; 3 * LOCAL],
    queued_stamp: [u32; LOCAL],
}

impl Brick {
    fn new() -> Box<Self> {
        Box::new(Brick {
            value: [0.0; LOCAL],
            value_stamp: [0; LOCAL],
            edge: [0; 3 * LOCAL],
            edge_stamp: [0; 3 * LOCAL],
            queued_stamp: [0; LOCAL],
        })
    }
}

/// The caches of one tracking call and the next.
#[derive(Default)]
pub struct Bricks {
    stamp: u32,
    /// Bricks per axis for the current lattice.
    dims: [u32; 3],
    /// Brick position → (stamp, pool index).
    table: Vec<(u32, u32)>,
    pool: Vec<Box<Brick>>,
    /// Bricks handed out in this call.
    used: usize,
}

impl Bricks {
    /// Starts a call on a lattice with `points` lattice points per axis.
    pub fn begin(&mut self, points: [u32; 3]) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // After 2³² calls, wipe the stamps once so that none can match by accident.
            for b in &mut self.pool {
                b.value_stamp.fill(0);
                b.edge_stamp.fill(0);
                b.queued_stamp.fill(0);
            }
            self.table.iter_mut().for_each(|e| e.0 = 0);
            self.stamp = 1;
        }
        let dims = points.map(|p| p.div_ceil(SIDE));
        if dims != self.dims {
            self.dims = dims;
            let n = dims.iter().map(|&d| d as usize).product();
            self.table.clear();
            self.table.resize(n, (0, NONE));
        }
        self.used = 0;
    }

    /// Bricks in use in this call and in the pool.
    pub fn counts(&self) -> (usize, usize) {
        (self.used, self.pool.len())
    }

    /// Bytes held (capacities).
    pub fn capacity_bytes(&self) -> usize {
        self.table.capacity() * 8
            + self.pool.capacity() * 8
            + self.pool.len() * std::mem::size_of::<Brick>()
    }

    #[inline]
    fn brick(&mut self, p: [u32; 3]) -> (usize, usize) {
        let b = [p[0] / SIDE, p[1] / SIDE, p[2] / SIDE];
        let t = b[0] as usize
            + self.dims[0] as usize * (b[1] as usize + self.dims[1] as usize * b[2] as usize);
        let l = (p[0] % SIDE) as usize
            + SIDE as usize * ((p[1] % SIDE) as usize + SIDE as usize * (p[2] % SIDE) as usize);
        let e = &mut self.table[t];
        if e.0 != self.stamp {
            if self.used == self.pool.len() {
                self.pool.push(Brick::new());
            }
            *e = (self.stamp, self.used as u32);
            self.used += 1;
        }
        (e.1 as usize, l)
    }

    /// The value at lattice point `p` if written in this call.
    #[inline]
    pub fn value(&mut self, p: [u32; 3]) -> Option<f64> {
        let (b, l) = self.brick(p);
        let br = &self.pool[b];
        (br.value_stamp[l] == self.stamp).then(|| br.value[l])
    }

    /// Marks `p` as pending (returns false when it was already known or pending).
    #[inline]
    pub fn claim_value(&mut self, p: [u32; 3]) -> bool {
        let (b, l) = self.brick(p);
        let s = self.stamp;
        let br = &mut self.pool[b];
        if br.value_stamp[l] == s {
            false
        } else {
            br.value_stamp[l] = s;
            br.value[l] = f64::NAN;
            true
        }
    }

    #[inline]
    pub fn set_value(&mut self, p: [u32; 3], v: f64) {
        let (b, l) = self.brick(p);
        let s = self.stamp;
        let br = &mut self.pool[b];
        br.value_stamp[l] = s;
        br.value[l] = v;
    }

    /// The value at `p`, which must have been written in this call.
    #[inline]
    pub fn known(&mut self, p: [u32; 3]) -> f64 {
        let (b, l) = self.brick(p);
        debug_assert_eq!(self.pool[b].value_stamp[l], self.stamp);
        self.pool[b].value[l]
    }

    /// The vertex on the edge from `p` along `axis`, creating it with `make` on first use.
    #[inline]
    pub fn edge(&mut self, p: [u32; 3], axis: u8, make: impl FnOnce(&mut Self) -> u32) -> u32 {
        let (b, l) = self.brick(p);
        let k = axis as usize * LOCAL + l;
        if self.pool[b].edge_stamp[k] == self.stamp {
            return self.pool[b].edge[k];
        }
        let v = make(self);
        let s = self.stamp;
        let br = &mut self.pool[b];
        br.edge_stamp[k] = s;
        br.edge[k] = v;
        v
    }

    /// Marks cell `c` as queued; false when it already was in this call.
    #[inline]
    pub fn queue(&mut self, c: [u32; 3]) -> bool {
        let (b, l) = self.brick(c);
        let s = self.stamp;
        let br = &mut self.pool[b];
        if br.queued_stamp[l] == s {
            false
        } else {
            br.queued_stamp[l] = s;
            true
        }
    }
}
