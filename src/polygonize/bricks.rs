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

/// Everything cached about one lattice point, in one record so that a lookup touches one
/// cache line: its value, the vertices on the three edges that start at it, and the "queued"
/// mark of the cell whose lower corner it is, each with its stamp.
#[derive(Clone, Copy, Default)]
#[repr(C)]
struct Point {
    value: f64,
    value_stamp: u32,
    queued_stamp: u32,
    edge: [u32; 3],
    edge_stamp: [u32; 3],
}

/// One brick of 8³ lattice points.
#[derive(Clone)]
struct Brick {
    points: [Point; LOCAL],
}

impl Brick {
    fn new() -> Box<Self> {
        Box::new(Brick {
            points: [Point::default(); LOCAL],
        })
    }
}

/// Offsets within a brick of the eight corners of a cell, in case-bit order (x fastest).
const CORNER_OFFSETS: [usize; 8] = [0, 1, 8, 9, 64, 65, 72, 73];

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
                b.points.fill(Point::default());
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
        let q = &self.pool[b].points[l];
        (q.value_stamp == self.stamp).then_some(q.value)
    }

    /// Marks `p` as pending (returns false when it was already known or pending).
    #[inline]
    pub fn claim_value(&mut self, p: [u32; 3]) -> bool {
        let (b, l) = self.brick(p);
        let s = self.stamp;
        let q = &mut self.pool[b].points[l];
        if q.value_stamp == s {
            false
        } else {
            q.value_stamp = s;
            q.value = f64::NAN;
            true
        }
    }

    /// Claims the corners of the cell with lower corner `o` (as [`Bricks::claim_value`]),
    /// calling `claimed` with each corner claimed now and its [`Slot`] for
    /// [`Bricks::set_slot`].
    #[inline]
    pub fn claim_cell(&mut self, o: [u32; 3], mut claimed: impl FnMut([u32; 3], Slot)) {
        let s = self.stamp;
        if let Some((b, l)) = self.cell_in_brick(o) {
            let pts = &mut self.pool[b].points;
            for (k, off) in CORNER_OFFSETS.iter().enumerate() {
                let q = &mut pts[l + off];
                if q.value_stamp != s {
                    q.value_stamp = s;
                    q.value = f64::NAN;
                    claimed(corner(o, k), Slot::new(b, l + off));
                }
            }
        } else {
            for k in 0..8 {
                let c = corner(o, k);
                let (b, l) = self.brick(c);
                let q = &mut self.pool[b].points[l];
                if q.value_stamp != s {
                    q.value_stamp = s;
                    q.value = f64::NAN;
                    claimed(c, Slot::new(b, l));
                }
            }
        }
    }

    /// Writes the value of a claimed point.
    #[inline]
    pub fn set_slot(&mut self, slot: Slot, v: f64) {
        let (b, l) = slot.get();
        self.pool[b].points[l].value = v;
    }

    #[inline]
    pub fn set_value(&mut self, p: [u32; 3], v: f64) {
        let (b, l) = self.brick(p);
        let s = self.stamp;
        let q = &mut self.pool[b].points[l];
        q.value_stamp = s;
        q.value = v;
    }

    /// The value at `p`, which must have been written in this call.
    #[inline]
    pub fn known(&mut self, p: [u32; 3]) -> f64 {
        let (b, l) = self.brick(p);
        debug_assert_eq!(self.pool[b].points[l].value_stamp, self.stamp);
        self.pool[b].points[l].value
    }

    /// The values at the eight corners of the cell with lower corner `o` (all written in this
    /// call), in case-bit order.
    #[inline]
    pub fn cell_values(&mut self, o: [u32; 3]) -> [f64; 8] {
        if let Some((b, l)) = self.cell_in_brick(o) {
            let pts = &self.pool[b].points;
            CORNER_OFFSETS.map(|off| pts[l + off].value)
        } else {
            [0, 1, 2, 3, 4, 5, 6, 7].map(|k| self.known(corner(o, k)))
        }
    }

    /// Brick and local index of `o` when the whole cell with lower corner `o` lies in one brick.
    #[inline]
    fn cell_in_brick(&mut self, o: [u32; 3]) -> Option<(usize, usize)> {
        if o.iter().all(|&c| c % SIDE < SIDE - 1) {
            Some(self.brick(o))
        } else {
            None
        }
    }

    /// The vertex on the edge from `p` along `axis`, creating it with `make` on first use.
    #[inline]
    pub fn edge(&mut self, p: [u32; 3], axis: u8, make: impl FnOnce(&mut Self) -> u32) -> u32 {
        let (b, l) = self.brick(p);
        let a = axis as usize;
        let q = &self.pool[b].points[l];
        if q.edge_stamp[a] == self.stamp {
            return q.edge[a];
        }
        let v = make(self);
        let s = self.stamp;
        let q = &mut self.pool[b].points[l];
        q.edge_stamp[a] = s;
        q.edge[a] = v;
        v
    }

    /// Marks cell `c` as queued; false when it already was in this call.
    #[inline]
    pub fn queue(&mut self, c: [u32; 3]) -> bool {
        let (b, l) = self.brick(c);
        let s = self.stamp;
        let q = &mut self.pool[b].points[l];
        if q.queued_stamp == s {
            false
        } else {
            q.queued_stamp = s;
            true
        }
    }
}

/// Where a claimed point lives: brick and local index, packed.
#[derive(Clone, Copy, Debug)]
pub struct Slot(u32);

impl Slot {
    #[inline]
    fn new(brick: usize, local: usize) -> Self {
        debug_assert!(brick < 1 << 23 && local < LOCAL);
        Slot(((brick as u32) << 9) | local as u32)
    }
    #[inline]
    fn get(self) -> (usize, usize) {
        ((self.0 >> 9) as usize, (self.0 & 511) as usize)
    }
}

/// Lattice point of corner `k` of the cell with lower corner `o`.
#[inline]
fn corner(o: [u32; 3], k: usize) -> [u32; 3] {
    [
        o[0] + (k & 1) as u32,
        o[1] + ((k >> 1) & 1) as u32,
        o[2] + ((k >> 2) & 1) as u32,
    ]
}
