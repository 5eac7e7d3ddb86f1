//! The octree of a partition-of-unity fit: a cube split into eight children until each leaf holds
//! at most `max_per_leaf` points. Every split creates all eight children, so the leaves tile the
//! cube (empty leaves included) and every point of the cube lies in exactly one leaf.

use glam::DVec3;
use rayon::prelude::*;

/// Depth at which leaves stop splitting whatever they hold (coincident points).
pub const MAX_DEPTH: u32 = 24;

/// One node: a cube, its children and the run of points it holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Centre of the cube.
    pub centre: DVec3,
    /// Half the side of the cube.
    pub half: f64,
    /// Index of the first of eight consecutive children; 0 for a leaf (the root is node 0, so no
    /// node has it as a child).
    pub children: u32,
    /// `order[start..end]` are the points inside the cube.
    pub start: u32,
    /// End of the run of the cube's points in `order` (see `start`).
    pub end: u32,
}

impl Node {
    /// Whether the node has no children.
    pub fn is_leaf(&self) -> bool {
        self.children == 0
    }

    /// Squared distance from `p` to the cube (0 inside).
    pub fn distance_squared(&self, p: DVec3) -> f64 {
        let d = ((p - self.centre).abs() - DVec3::splat(self.half)).max(DVec3::ZERO);
        d.length_squared()
    }

    /// Squared distance from `p` to the farthest corner of the cube widened by a millionth of
    /// its half side: every point of the cube is nearer to `p`, rounding included.
    fn farthest_squared(&self, p: DVec3) -> f64 {
        ((p - self.centre).abs() + DVec3::splat(self.half * (1.0 + 1e-6))).length_squared()
    }

    /// Half the diagonal of the cube.
    pub fn half_diagonal(&self) -> f64 {
        self.half * 3f64.sqrt()
    }
}

/// An octree over a point set.
#[derive(Clone, Debug)]
pub struct Octree {
    /// The nodes, the root first.
    pub nodes: Vec<Node>,
    /// Point indices, grouped by node (each node's run splits into its children's runs, in
    /// child order); increasing within a leaf.
    pub order: Vec<u32>,
    /// The points in the order of `order` (`sorted[k]` = `points[order[k]]`), so that the
    /// queries read each leaf's points from one run of memory; empty after
    /// [`Octree::release_copy`].
    sorted: Vec<DVec3>,
    /// The leaves' node indices, in node order.
    pub leaves: Vec<u32>,
    /// For each node, its position in `leaves` (`u32::MAX` for inner nodes).
    pub leaf_slot: Vec<u32>,
}

/// Which child of a node centred at `c` holds `p`: bit 0 for x ≥ c.x, bit 1 for y, bit 2 for z.
fn octant(p: DVec3, c: DVec3) -> usize {
    (p.x >= c.x) as usize | ((p.y >= c.y) as usize) << 1 | ((p.z >= c.z) as usize) << 2
}

/// The nodes still to visit in a depth-first walk, without allocating: a walk holds at most 7
/// siblings per level below the root's 1.
struct NodeStack {
    nodes: [u32; 8 * MAX_DEPTH as usize + 8],
    len: usize,
}

impl NodeStack {
    fn root() -> Self {
        NodeStack {
            nodes: [0; 8 * MAX_DEPTH as usize + 8],
            len: 1,
        }
    }

    #[inline(always)]
    fn push(&mut self, k: u32) {
        self.nodes[self.len] = k;
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<u32> {
        self.len = self.len.checked_sub(1)?;
        Some(self.nodes[self.len])
    }
}

/// A node's run: its centre, its indices and points, and as much scratch space for each.
type Run<'a> = (
    DVec3,
    &'a mut [u32],
    &'a mut [DVec3],
    &'a mut [u32],
    &'a mut [DVec3],
);

/// The `a..b` part of `*rest`, which starts at `offset`; `*rest` then starts at `b`.
fn take_run<'a, T>(rest: &mut &'a mut [T], offset: usize, a: usize, b: usize) -> &'a mut [T] {
    let (_, r) = std::mem::take(rest).split_at_mut(a - offset);
    let (run, r) = r.split_at_mut(b - a);
    *rest = r;
    run
}

/// The runs of the nodes `splitting` (whose runs are disjoint and increasing) in `order` and
/// `sorted`, with the same ranges of the scratch `spare_order` and `spare_sorted`.
fn disjoint_runs<'a>(
    nodes: &[Node],
    splitting: &[usize],
    mut order: &'a mut [u32],
    mut sorted: &'a mut [DVec3],
    mut spare_order: &'a mut [u32],
    mut spare_sorted: &'a mut [DVec3],
) -> Vec<Run<'a>> {
    let mut offset = 0;
    let mut runs = Vec::with_capacity(splitting.len());
    for &k in splitting {
        let n = &nodes[k];
        let (a, b) = (n.start as usize, n.end as usize);
        runs.push((
            n.centre,
            take_run(&mut order, offset, a, b),
            take_run(&mut sorted, offset, a, b),
            take_run(&mut spare_order, offset, a, b),
            take_run(&mut spare_sorted, offset, a, b),
        ));
        offset = b;
    }
    runs
}

/// The runs of the nodes `splitting` (whose runs are disjoint and increasing) in `order` and
/// `sorted`.
fn disjoint_runs_in_place<'a>(
    nodes: &[Node],
    splitting: &[usize],
    mut order: &'a mut [u32],
    mut sorted: &'a mut [DVec3],
) -> Vec<(DVec3, &'a mut [u32], &'a mut [DVec3])> {
    let mut offset = 0;
    let mut runs = Vec::with_capacity(splitting.len());
    for &k in splitting {
        let n = &nodes[k];
        let (a, b) = (n.start as usize, n.end as usize);
        runs.push((
            n.centre,
            take_run(&mut order, offset, a, b),
            take_run(&mut sorted, offset, a, b),
        ));
        offset = b;
    }
    runs
}

/// Where each octant's run starts among `pts` sorted stably by octant of `centre` (and, at 8,
/// the end).
fn octant_bounds(pts: &[DVec3], centre: DVec3) -> [usize; 9] {
    let mut bounds = [0usize; 9];
    for p in pts.iter() {
        bounds[octant(*p, centre) + 1] += 1;
    }
    for o in 0..8 {
        bounds[o + 1] += bounds[o];
    }
    bounds
}

/// [`split_run`] through `scratch` (grown to the run's length), for the short runs of
/// [`Octree::refined`].
fn split_run_in_place(
    (centre, run, pts): (DVec3, &mut [u32], &mut [DVec3]),
    scratch: &mut Vec<(u32, DVec3)>,
) -> [usize; 9] {
    scratch.clear();
    scratch.extend(run.iter().copied().zip(pts.iter().copied()));
    let bounds = octant_bounds(pts, centre);
    let mut fill = bounds;
    for &(i, p) in scratch.iter() {
        let slot = &mut fill[octant(p, centre)];
        run[*slot] = i;
        pts[*slot] = p;
        *slot += 1;
    }
    bounds
}

/// Sorts a node's run (indices and points) by octant of its centre, stably, through the
/// run's scratch space; returns where each octant's run starts (and, at 8, the end).
fn split_run((centre, run, pts, spare_run, spare_pts): Run<'_>) -> [usize; 9] {
    let bounds = octant_bounds(pts, centre);
    let mut fill = bounds;
    for (&i, p) in run.iter().zip(pts.iter()) {
        let slot = &mut fill[octant(*p, centre)];
        spare_run[*slot] = i;
        spare_pts[*slot] = *p;
        *slot += 1;
    }
    run.copy_from_slice(spare_run);
    pts.copy_from_slice(spare_pts);
    bounds
}

impl Octree {
    /// Splits the cube (`centre`, `half`) until each leaf holds at most `max_per_leaf` of
    /// `points` (all inside the cube).
    pub fn new(points: &[DVec3], centre: DVec3, half: f64, max_per_leaf: usize) -> Octree {
        Self::build(points, centre, half, |n| {
            (n.end - n.start) as usize > max_per_leaf
        })
    }

    /// Splits the cube (`centre`, `half`), holding `points` (all inside it), wherever `split`
    /// says so (and the depth is below 24).
    pub fn build(
        points: &[DVec3],
        centre: DVec3,
        half: f64,
        split: impl Fn(&Node) -> bool + Sync,
    ) -> Octree {
        let mut nodes = vec![Node {
            centre,
            half,
            children: 0,
            start: 0,
            end: points.len() as u32,
        }];
        // Written in parallel. The splits' scratch space is first written by the root's
        // split and reused by every level below.
        let mut order: Vec<u32> = (0..points.len() as u32).into_par_iter().collect();
        let mut sorted: Vec<DVec3> = points.par_iter().copied().collect();
        let mut spare_order = vec![0u32; points.len()];
        let mut spare_sorted = vec![DVec3::ZERO; points.len()];
        let mut depth = vec![0u32];
        // Level by level (the nodes of one level are consecutive, their runs disjoint and
        // increasing): the decisions and the splits of the runs in parallel, the children in
        // node order.
        let mut level = 0..1;
        while !level.is_empty() {
            let splitting: Vec<usize> = nodes[level.clone()]
                .par_iter()
                .zip(&depth[level.clone()])
                .zip(level.clone())
                .filter_map(|((n, &d), k)| (d < MAX_DEPTH && split(n)).then_some(k))
                .collect();
            let runs = disjoint_runs(
                &nodes,
                &splitting,
                &mut order,
                &mut sorted,
                &mut spare_order,
                &mut spare_sorted,
            );
            let bounds: Vec<[usize; 9]> = runs.into_par_iter().map(split_run).collect();
            let next = nodes.len();
            for (&k, bounds) in splitting.iter().zip(bounds) {
                let n = nodes[k];
                let first = nodes.len() as u32;
                nodes[k].children = first;
                let h = 0.5 * n.half;
                for o in 0..8 {
                    let sign = |bit: usize| if o >> bit & 1 == 1 { h } else { -h };
                    nodes.push(Node {
                        centre: n.centre + DVec3::new(sign(0), sign(1), sign(2)),
                        half: h,
                        children: 0,
                        start: n.start + bounds[o] as u32,
                        end: n.start + bounds[o + 1] as u32,
                    });
                    depth.push(depth[k] + 1);
                }
            }
            level = next..nodes.len();
        }
        Octree {
            order,
            sorted,
            ..Octree::from_nodes(nodes)
        }
    }

    /// This octree split further: a node is split where this one is, and a leaf of it (or a
    /// node below one) where `split(self, node)` says so (and the depth is below 24). The
    /// result is the tree [`Octree::build`] gives for that rule, node for node. `split` sees
    /// this tree while its points are sorted further within its leaves, which changes no
    /// query's answer. The points are sorted in place: no copy of them is made.
    pub fn refined(mut self, split: impl Fn(&Octree, &Node) -> bool + Sync) -> Octree {
        let mut nodes = vec![self.nodes[0]];
        nodes[0].children = 0;
        let mut depth = vec![0u32];
        // The node of `self` each node stands for (`u32::MAX` below a leaf of `self`).
        let mut from = vec![0u32];
        let mut level = 0..1;
        while !level.is_empty() {
            let here = &self;
            // The node of `self` node `k` stands for, when `self` splits it.
            let mirror = |k: usize| {
                (from[k] != u32::MAX)
                    .then(|| here.nodes[from[k] as usize])
                    .filter(|m| !m.is_leaf())
            };
            let splitting: Vec<usize> = level
                .clone()
                .into_par_iter()
                .filter(|&k| {
                    mirror(k).is_some() || (depth[k] < MAX_DEPTH && split(here, &nodes[k]))
                })
                .collect();
            // The runs of the nodes split below the leaves of `self`, each sorted by octant
            // (those `self` splits are sorted already).
            let mirrors: Vec<Option<Node>> = splitting.iter().map(|&k| mirror(k)).collect();
            let fresh: Vec<usize> = splitting
                .iter()
                .zip(&mirrors)
                .filter_map(|(&k, m)| m.is_none().then_some(k))
                .collect();
            let runs = disjoint_runs_in_place(&nodes, &fresh, &mut self.order, &mut self.sorted);
            let bounds: Vec<[usize; 9]> = runs
                .into_par_iter()
                .map_init(Vec::new, |scratch, run| split_run_in_place(run, scratch))
                .collect();
            let mut fresh_bounds = bounds.into_iter();
            let next = nodes.len();
            for (&k, &mirror) in splitting.iter().zip(&mirrors) {
                let n = nodes[k];
                let first = nodes.len() as u32;
                nodes[k].children = first;
                let h = 0.5 * n.half;
                let b = match mirror {
                    None => fresh_bounds.next().expect("a fresh split has its bounds"),
                    Some(_) => [0; 9],
                };
                for o in 0..8 {
                    let sign = |bit: usize| if o >> bit & 1 == 1 { h } else { -h };
                    let centre = n.centre + DVec3::new(sign(0), sign(1), sign(2));
                    let (start, end, source) = match mirror {
                        Some(m) => {
                            let c = m.children + o as u32;
                            let child = &self.nodes[c as usize];
                            debug_assert_eq!((child.centre, child.half), (centre, h));
                            (child.start, child.end, c)
                        }
                        None => (n.start + b[o] as u32, n.start + b[o + 1] as u32, u32::MAX),
                    };
                    nodes.push(Node {
                        centre,
                        half: h,
                        children: 0,
                        start,
                        end,
                    });
                    depth.push(depth[k] + 1);
                    from.push(source);
                }
            }
            level = next..nodes.len();
        }
        Octree {
            order: std::mem::take(&mut self.order),
            sorted: std::mem::take(&mut self.sorted),
            ..Octree::from_nodes(nodes)
        }
    }

    /// The octree of `nodes` (as [`Octree::nodes`] lists them, children after their parent),
    /// without points: `order` is empty.
    pub fn from_nodes(nodes: Vec<Node>) -> Octree {
        let mut leaves = Vec::new();
        let mut leaf_slot = vec![u32::MAX; nodes.len()];
        for (i, n) in nodes.iter().enumerate() {
            if n.is_leaf() {
                leaf_slot[i] = leaves.len() as u32;
                leaves.push(i as u32);
            }
        }
        Octree {
            nodes,
            order: Vec::new(),
            sorted: Vec::new(),
            leaves,
            leaf_slot,
        }
    }

    /// The octree split only where its nodes meet the box `[lo, hi]` (with the margin of
    /// [`Octree::for_each_leaf_meeting_box`]): a node that does not meet it is a leaf. Every
    /// point of the box clamped into the root cube descends to a leaf of the same cube as in
    /// `self`. Without points (`order` empty, runs zero).
    pub fn pruned_to_box(&self, lo: DVec3, hi: DVec3) -> Octree {
        let bare = |n: &Node| Node {
            children: 0,
            start: 0,
            end: 0,
            ..*n
        };
        let mut nodes = vec![bare(&self.nodes[0])];
        // The node of `self` each node of the pruned tree stands for.
        let mut from = vec![0u32];
        let mut k = 0;
        while k < nodes.len() {
            let n = &self.nodes[from[k] as usize];
            if !n.is_leaf() && self.meets_box(n, lo, hi) {
                nodes[k].children = nodes.len() as u32;
                for c in n.children..n.children + 8 {
                    nodes.push(bare(&self.nodes[c as usize]));
                    from.push(c);
                }
            }
            k += 1;
        }
        Octree::from_nodes(nodes)
    }

    /// Whether node `n`'s cube, widened by a millionth of the root's half side, meets the
    /// closed box `[lo, hi]`.
    fn meets_box(&self, n: &Node, lo: DVec3, hi: DVec3) -> bool {
        let reach = DVec3::splat(n.half + 1e-6 * self.nodes[0].half);
        !((n.centre - reach).cmpgt(hi).any() || (n.centre + reach).cmplt(lo).any())
    }

    /// The root cube's corners.
    pub fn cube(&self) -> (DVec3, DVec3) {
        let r = &self.nodes[0];
        (r.centre - r.half, r.centre + r.half)
    }

    /// The leaf holding `p` clamped into the root cube, as its position in `leaves`.
    pub fn leaf_of(&self, p: DVec3) -> u32 {
        let (lo, hi) = self.cube();
        let p = p.clamp(lo, hi);
        let mut k = 0usize;
        loop {
            let n = &self.nodes[k];
            if n.is_leaf() {
                return self.leaf_slot[k];
            }
            k = n.children as usize + octant(p, n.centre);
        }
    }

    /// Calls `visit(node)` for every leaf whose cube meets the closed ball (`c`, `r`).
    pub fn for_each_leaf_meeting(&self, c: DVec3, r: f64, mut visit: impl FnMut(u32)) {
        let r2 = r * r;
        let mut stack = NodeStack::root();
        while let Some(k) = stack.pop() {
            let n = &self.nodes[k as usize];
            if n.distance_squared(c) > r2 {
                continue;
            }
            if n.is_leaf() {
                visit(k);
            } else {
                // Reverse order so that children are visited in increasing order.
                (0..8).rev().for_each(|o| stack.push(n.children + o));
            }
        }
    }

    /// Calls `visit(node)` for every leaf whose cube meets the closed box `[lo, hi]` (cubes
    /// widened by a millionth of the root's half side, so that a leaf a point of the box
    /// descends into is never left out by rounding of its corners).
    pub fn for_each_leaf_meeting_box(&self, lo: DVec3, hi: DVec3, mut visit: impl FnMut(u32)) {
        let mut stack = NodeStack::root();
        while let Some(k) = stack.pop() {
            let n = &self.nodes[k as usize];
            if !self.meets_box(n, lo, hi) {
                continue;
            }
            if n.is_leaf() {
                visit(k);
            } else {
                (0..8).rev().for_each(|o| stack.push(n.children + o));
            }
        }
    }

    /// Number of `points` within the closed ball (`c`, `r`).
    pub fn count_within(&self, points: &[DVec3], c: DVec3, r: f64) -> usize {
        self.count_within_up_to(points, c, r, usize::MAX)
    }

    /// Whether more than `limit` of `points` lie within the closed ball (`c`, `r`); stops
    /// counting once they do.
    pub fn more_within_than(&self, points: &[DVec3], c: DVec3, r: f64, limit: usize) -> bool {
        self.count_within_up_to(points, c, r, limit) > limit
    }

    /// Walks the nodes meeting the closed ball (`c`, `r2` its squared radius) down to those
    /// inside it (`visit(k, node, true)`, `k` the node's index) and the leaves it cuts
    /// (`visit(k, leaf, false)`); stops when `visit` returns true.
    fn walk_ball(&self, c: DVec3, r2: f64, mut visit: impl FnMut(u32, &Node, bool) -> bool) {
        let mut stack = NodeStack::root();
        while let Some(k) = stack.pop() {
            let n = &self.nodes[k as usize];
            if n.distance_squared(c) > r2 {
                continue;
            }
            let inside = n.farthest_squared(c) <= r2;
            if inside || n.is_leaf() {
                if visit(k, n, inside) {
                    return;
                }
            } else {
                (0..8).for_each(|o| stack.push(n.children + o));
            }
        }
    }

    /// The number of `points` within the closed ball (`c`, `r`), or some number above `limit`
    /// once more than `limit` are found. Nodes inside the ball count whole.
    pub fn count_within_up_to(&self, points: &[DVec3], c: DVec3, r: f64, limit: usize) -> usize {
        let r2 = r * r;
        let mut count = 0;
        self.walk_ball(c, r2, |_, n, inside| {
            if inside {
                count += (n.end - n.start) as usize;
            } else {
                self.for_each_point(points, n, |_, p| {
                    count += ((p - c).length_squared() <= r2) as usize
                });
            }
            count > limit
        });
        count
    }

    /// The number of points within the closed ball (`c`, `r`) whose position `k` in `order`
    /// has `keep(k)`, or some number above `limit` once more than `limit` are found; `kept(j)`
    /// is that number for node `j` (for the nodes inside the ball). Reads the tree's copy of
    /// the points (which it must have).
    pub fn count_kept_within_up_to(
        &self,
        c: DVec3,
        r: f64,
        limit: usize,
        kept: impl Fn(u32) -> usize,
        keep: impl Fn(usize) -> bool,
    ) -> usize {
        let r2 = r * r;
        let mut count = 0;
        self.walk_ball(c, r2, |j, n, inside| {
            if inside {
                count += kept(j);
            } else {
                let (start, end) = (n.start as usize, n.end as usize);
                for (k, p) in (start..end).zip(&self.sorted[start..end]) {
                    count += (keep(k) & ((*p - c).length_squared() <= r2)) as usize;
                }
            }
            count > limit
        });
        count
    }

    /// Calls `visit(i, p)` for every point `i` within the closed ball (`c`, `r`) whose
    /// position `k` in `order` has `keep(k)`, leaf by leaf. Reads the tree's copy of the points
    /// (which it must have).
    pub fn for_each_kept_within(
        &self,
        c: DVec3,
        r: f64,
        keep: impl Fn(usize) -> bool,
        mut visit: impl FnMut(u32, DVec3),
    ) {
        let r2 = r * r;
        self.for_each_leaf_meeting(c, r, |j| {
            let n = &self.nodes[j as usize];
            for k in n.start as usize..n.end as usize {
                if keep(k) {
                    let p = self.sorted[k];
                    if (p - c).length_squared() <= r2 {
                        visit(self.order[k], p);
                    }
                }
            }
        });
    }

    /// Whether some point `i` of `points` within the closed ball (`c`, `r`) has `pred(i)`;
    /// stops at the first.
    pub fn any_within(
        &self,
        points: &[DVec3],
        c: DVec3,
        r: f64,
        pred: impl Fn(u32) -> bool,
    ) -> bool {
        let r2 = r * r;
        let mut found = false;
        self.walk_ball(c, r2, |_, n, inside| {
            if inside {
                found = self.order[n.start as usize..n.end as usize]
                    .iter()
                    .any(|&i| pred(i));
            } else {
                self.for_each_point(points, n, |i, p| {
                    found |= (p - c).length_squared() <= r2 && pred(i)
                });
            }
            found
        });
        found
    }

    /// Distance from `c` to its `k`-th nearest point of `points` (`k` ≥ 1; the farthest point
    /// when there are fewer; infinite when there are none), visiting the nodes nearest first.
    pub fn kth_nearest_distance(&self, points: &[DVec3], c: DVec3, k: usize) -> f64 {
        use std::cmp::Reverse;
        use std::collections::BinaryHeap;
        // Squared distances are non-negative, so their bit patterns order like the values.
        let mut best: BinaryHeap<u64> = BinaryHeap::with_capacity(k + 1);
        let mut queue = BinaryHeap::new();
        queue.push(Reverse((self.nodes[0].distance_squared(c).to_bits(), 0u32)));
        while let Some(Reverse((d2, node))) = queue.pop() {
            if best.len() == k && d2 >= *best.peek().unwrap() {
                break;
            }
            let n = &self.nodes[node as usize];
            if n.is_leaf() {
                self.for_each_point(points, n, |_, p| {
                    let e = (p - c).length_squared().to_bits();
                    if best.len() < k {
                        best.push(e);
                    } else if e < *best.peek().unwrap() {
                        best.pop();
                        best.push(e);
                    }
                });
            } else {
                for o in 0..8 {
                    let ch = n.children + o;
                    let d = self.nodes[ch as usize].distance_squared(c);
                    queue.push(Reverse((d.to_bits(), ch)));
                }
            }
        }
        best.peek()
            .map_or(f64::INFINITY, |&b| f64::from_bits(b).sqrt())
    }

    /// Distances from `c` to its `k`-th nearest point of `points` (as
    /// [`Octree::kth_nearest_distance`]) and to its nearest. The points within `guess` of `c`
    /// are gathered (their squared distances into `scratch`), in balls twice as wide until
    /// they are at least `k`, and the `k`-th picked by selection: with a guess near the answer
    /// this is one walk of the tree, cheaper than the nearest-first walk; with a guess far too
    /// small or too large, many walks or many points.
    pub fn nearest_distances(
        &self,
        points: &[DVec3],
        c: DVec3,
        k: usize,
        guess: f64,
        scratch: &mut Vec<f64>,
    ) -> (f64, f64) {
        let total = self.order.len();
        let k = k.clamp(1, total.max(1));
        let mut r = guess;
        loop {
            scratch.clear();
            let r2 = r * r;
            self.for_each_leaf_meeting(c, r, |leaf| {
                self.for_each_point(points, &self.nodes[leaf as usize], |_, p| {
                    let e = (p - c).length_squared();
                    if e <= r2 {
                        scratch.push(e);
                    }
                })
            });
            if scratch.len() >= k || scratch.len() == total {
                break;
            }
            r = if r > 0.0 { 2.0 * r } else { self.nodes[0].half };
        }
        if scratch.is_empty() {
            return (f64::INFINITY, f64::INFINITY);
        }
        let k = k.min(scratch.len());
        let (before, kth, _) = scratch.select_nth_unstable_by(k - 1, f64::total_cmp);
        let nearest = before.iter().fold(*kth, |a, &b| a.min(b));
        (kth.sqrt(), nearest.sqrt())
    }

    /// Calls `visit(i)` for every point `points[i]` within the closed ball (`c`, `r`).
    pub fn for_each_within(&self, points: &[DVec3], c: DVec3, r: f64, mut visit: impl FnMut(u32)) {
        let r2 = r * r;
        self.for_each_leaf_meeting(c, r, |k| {
            self.for_each_point(points, &self.nodes[k as usize], |i, p| {
                if (p - c).length_squared() <= r2 {
                    visit(i);
                }
            });
        });
    }

    /// Calls `visit(i, k, points[i])` for every point `i` within `r` of `c`, with `k` its
    /// position in `order` (`order[k] = i`), leaf by leaf.
    pub fn for_each_within_ranked(
        &self,
        points: &[DVec3],
        c: DVec3,
        r: f64,
        mut visit: impl FnMut(u32, u32, DVec3),
    ) {
        let r2 = r * r;
        self.for_each_leaf_meeting(c, r, |k| {
            let n = &self.nodes[k as usize];
            let mut at = n.start;
            self.for_each_point(points, n, |i, p| {
                if (p - c).length_squared() <= r2 {
                    visit(i, at, p);
                }
                at += 1;
            });
        });
    }

    /// Calls `f(i, points[i])` for the points of node `n`, in the order of its run of `order`
    /// (`points` are those the tree was built from): read from the tree's own copy while it
    /// has one.
    #[inline(always)]
    fn for_each_point(&self, points: &[DVec3], n: &Node, mut f: impl FnMut(u32, DVec3)) {
        let (start, end) = (n.start as usize, n.end as usize);
        let run = &self.order[start..end];
        if self.sorted.is_empty() {
            run.iter().for_each(|&i| f(i, points[i as usize]));
        } else {
            run.iter()
                .zip(&self.sorted[start..end])
                .for_each(|(&i, &p)| f(i, p));
        }
    }

    /// The point at position `k` of `order`, read from the tree's copy (which it must have).
    pub fn point_at(&self, k: usize) -> DVec3 {
        self.sorted[k]
    }

    /// Whether the queries read the points from the tree's own copy (the `points` they are
    /// given are then not read).
    pub fn has_copy(&self) -> bool {
        self.sorted.len() == self.order.len()
    }

    /// Frees the tree's copy of its points (the queries then read `points` through `order`).
    pub fn release_copy(&mut self) {
        self.take_copy();
    }

    /// The tree's copy of its points (`copy[k]` = `points[order[k]]`), which it no longer keeps
    /// (as after [`Octree::release_copy`]).
    pub fn take_copy(&mut self) -> Vec<DVec3> {
        std::mem::take(&mut self.sorted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::random_points;

    /// The leaves meeting a box hold every point of it (its corners and faces included) and
    /// are fewer than those meeting the ball around it.
    #[test]
    fn leaves_meeting_a_box_hold_its_points() {
        let pts = random_points(3000, -0.9, 0.9, 21);
        let t = Octree::new(&pts, DVec3::ZERO, 1.0, 20);
        let (lo, hi) = (DVec3::new(-0.5, 0.0, -1.0), DVec3::new(0.0, 0.25, -0.25));
        let (mut in_box, mut in_ball) = (Vec::new(), 0);
        t.for_each_leaf_meeting_box(lo, hi, |k| in_box.push(t.leaf_slot[k as usize]));
        t.for_each_leaf_meeting(0.5 * (lo + hi), 0.5 * (hi - lo).length(), |_| in_ball += 1);
        assert!(in_box.len() < in_ball);
        let inside = random_points(2000, 0.0, 1.0, 5)
            .into_iter()
            .map(|q| lo + (hi - lo) * q)
            .chain([
                lo,
                hi,
                DVec3::new(-0.5, 0.25, -0.25),
                DVec3::new(-0.25, 0.0, -0.5),
            ]);
        for p in inside {
            assert!(in_box.contains(&t.leaf_of(p)), "{p}");
        }
    }

    /// Splitting a tree further gives the tree built at once with both rules, node for node,
    /// with the same order of points.
    #[test]
    fn a_refined_tree_is_the_tree_built_with_both_rules() {
        let mut pts = random_points(4000, -0.9, 0.9, 5);
        // A dense cluster, and coincident points that stop at the largest depth.
        pts.extend(random_points(600, 0.2, 0.21, 6));
        pts.extend(std::iter::repeat_n(DVec3::new(-0.3, 0.4, 0.1), 80));
        for (per_leaf, limit) in [(40usize, 120usize), (16, 30), (200, 1000)] {
            let coarse = Octree::new(&pts, DVec3::ZERO, 1.0, per_leaf);
            let wanted = |t: &Octree, n: &Node| {
                t.more_within_than(&pts, n.centre, 1.2 * n.half_diagonal(), limit)
            };
            let once = Octree::build(&pts, DVec3::ZERO, 1.0, |n| {
                (n.end - n.start) as usize > per_leaf || wanted(&coarse, n)
            });
            let refined = coarse.clone().refined(wanted);
            assert!(refined.nodes.len() > coarse.nodes.len(), "{per_leaf}");
            assert_eq!(refined.nodes, once.nodes);
            assert_eq!(refined.order, once.order);
            assert_eq!(refined.sorted, once.sorted);
            assert_eq!(refined.leaves, once.leaves);
            assert_eq!(refined.leaf_slot, once.leaf_slot);
        }
    }

    #[test]
    fn leaves_tile_the_cube_and_hold_their_points() {
        let pts = random_points(3000, -0.9, 0.9, 21);
        let t = Octree::new(&pts, DVec3::ZERO, 1.0, 50);
        // Every point is in exactly one leaf, which contains it.
        let mut seen = vec![0u32; pts.len()];
        for &k in &t.leaves {
            let n = &t.nodes[k as usize];
            assert!(n.end - n.start <= 50);
            for &i in &t.order[n.start as usize..n.end as usize] {
                seen[i as usize] += 1;
                assert_eq!(n.distance_squared(pts[i as usize]), 0.0);
                assert_eq!(t.leaf_of(pts[i as usize]), t.leaf_slot[k as usize]);
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
        // The leaves' volumes add up to the cube's.
        let volume: f64 = t
            .leaves
            .iter()
            .map(|&k| (2.0 * t.nodes[k as usize].half).powi(3))
            .sum();
        assert!((volume - 8.0).abs() < 1e-9);
        // Ball queries agree with brute force.
        for (c, r) in [(DVec3::new(0.1, -0.2, 0.3), 0.25), (DVec3::splat(1.5), 0.7)] {
            let mut got = Vec::new();
            t.for_each_within(&pts, c, r, |i| got.push(i));
            got.sort_unstable();
            let want: Vec<u32> = (0..pts.len() as u32)
                .filter(|&i| (pts[i as usize] - c).length_squared() <= r * r)
                .collect();
            assert_eq!(got, want);
            // Without the tree's copy of the points: the same answers.
            let mut bare = t.clone();
            bare.release_copy();
            let mut again = Vec::new();
            bare.for_each_within(&pts, c, r, |i| again.push(i));
            again.sort_unstable();
            assert_eq!(again, want);
            assert_eq!(bare.count_within(&pts, c, r), want.len());
            assert_eq!(
                bare.kth_nearest_distance(&pts, c, 7),
                t.kth_nearest_distance(&pts, c, 7)
            );
            assert!(!t.more_within_than(&pts, c, r, want.len()), "{c:?} {r}");
            assert!(want.is_empty() || t.more_within_than(&pts, c, r, want.len() - 1));
        }
        // k-th nearest distances agree with sorting.
        for c in [DVec3::ZERO, DVec3::new(0.9, -0.9, 0.2), DVec3::splat(2.0)] {
            let mut d: Vec<f64> = pts.iter().map(|p| (*p - c).length()).collect();
            d.sort_by(f64::total_cmp);
            for k in [1, 7, 64, 3000] {
                assert_eq!(t.kth_nearest_distance(&pts, c, k), d[k - 1]);
                // From guesses too small, right and too large: the same, and the nearest.
                let mut scratch = Vec::new();
                for guess in [0.0, 1e-3, d[k - 1], 10.0] {
                    let got = t.nearest_distances(&pts, c, k, guess, &mut scratch);
                    assert_eq!(got, (d[k - 1], d[0]), "k {k} guess {guess}");
                }
            }
        }
        // More than there are: the farthest; none: infinite.
        let mut scratch = Vec::new();
        let far = t.nearest_distances(&pts, DVec3::ZERO, pts.len() + 5, 0.1, &mut scratch);
        assert_eq!(far.0, t.kth_nearest_distance(&pts, DVec3::ZERO, pts.len()));
        let none = Octree::new(&[], DVec3::ZERO, 1.0, 8);
        assert_eq!(
            none.nearest_distances(&[], DVec3::ZERO, 3, 0.5, &mut scratch),
            (f64::INFINITY, f64::INFINITY)
        );
    }
}
