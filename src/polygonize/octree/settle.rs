//! Settling the leaves by the signs of their corners (the corner test): a leaf whose corners all
//! have one sign holds no surface, one whose corners have both is crossed, and of a crossed leaf
//! only the ends of its crossed edges need values.
//!
//! Signs are first inferred from the balls of the values the levels left and from the blocks
//! they decided, then the leaves' corners still without one are claimed and evaluated in one
//! batch, then signs are inferred again; the ends of crossed edges that only have a sign are
//! evaluated last.

use super::balls::{balls, block_reach, Reach};
use super::block::{block_offset, LEAF_CORNERS, LEAF_POINTS};
use super::repair::Suspects;
use super::run::Run;
use super::state::{atomic_states, PointState};
use crate::error::Result;
use crate::field::Field;
use crate::polygonize::bits::set_bits;
use crate::polygonize::evaluate;
use crate::polygonize::table::EDGES;
use rayon::prelude::*;

/// What the settling keeps from one step to the next, besides the run's masks of undecided
/// leaves.
struct Settling {
    /// Per block of leaves, its crossed leaves (a mask of children).
    crossed: Vec<u8>,
    /// Per block, the points its undecided leaves need that had no sign when last settled.
    open: Vec<u32>,
    /// The block points within reach of each block point's ball (see [`Reach`]).
    reach: Box<[[Reach; 27]; 27]>,
    /// The crossed edges' ends to evaluate.
    ends: Ends,
}

/// The ends of crossed edges to evaluate, as (block, block points), and whether two blocks
/// inferred different signs for a point (the premise failing; the first sign is kept, so the
/// other block's leaves were decided with signs the store does not have).
#[derive(Default)]
struct Ends {
    blocks: Vec<(u32, u32)>,
    disagreed: bool,
    /// Where the premise failed, for the repair.
    suspects: Suspects,
}

/// What one settling step found in one block of leaves (bits of block points).
#[derive(Clone, Copy)]
struct Inferred {
    /// The block's index.
    block: u32,
    /// The points whose signs were inferred negative here.
    negative: u32,
    /// The points whose signs were inferred zero or positive here.
    positive: u32,
    /// The ends of the newly crossed leaves' crossed edges that have a sign but no value.
    ends: u32,
}

impl<F: Field + ?Sized> Run<'_, F> {
    /// Settles the leaves in `masks` by signs (see the module docs); `masks` become the crossed
    /// leaves, every corner of which has a value or a sign, and every crossed edge's ends a
    /// value. Where the premise failed, `suspects` says where.
    pub(super) fn settle_by_signs(&mut self) -> Result<()> {
        let n = self.blocks.len();
        let mut settling = Settling {
            crossed: vec![0u8; n],
            open: vec![0u32; n],
            reach: block_reach(self.lattice.cell(), self.safety),
            ends: Ends::default(),
        };
        // Every point the leaves may need, signs inferred or values, has slots from here on.
        for (&o, &m) in self.blocks.iter().zip(&self.masks) {
            if m != 0 {
                self.store.give_block_bricks(o, self.lattice.cells());
            }
        }
        // First with the signs of the blocks the levels decided, on the faces, edges and
        // corners the blocks share with them (only needed then: the leaves' corners without a
        // sign are never more than before).
        self.settle(&mut settling, true);
        self.known = Vec::new();
        self.evaluate_unsigned_corners(&settling.open)?;
        self.settle(&mut settling, false);
        debug_assert!(self.masks.iter().all(|&m| m == 0));
        let Settling { crossed, ends, .. } = settling;
        self.suspects = self.evaluate_crossed_edge_ends(&crossed, ends)?;
        self.masks = crossed;
        Ok(())
    }

    /// Claims the corners still without a sign (`open`, per block) and evaluates them in one
    /// batch.
    fn evaluate_unsigned_corners(&mut self, open: &[u32]) -> Result<()> {
        self.points = self.store.claim_blocks(&self.blocks, open, self.lattice);
        self.evaluate_points()
    }

    /// One settling step: signs are inferred ([`balls`]) for the corners the undecided leaves
    /// in `masks` need (a point in balls of both signs, where the premise fails, gets none),
    /// then every leaf whose corners all have a sign leaves `masks`: into `crossed` when they
    /// have both signs, nowhere when they have one. The signs inferred are stored in the points'
    /// states, and the blocks of the leaves newly crossed are added to `ends` with the ends of
    /// their crossed edges that have a sign but no value. The `first` step also takes the signs
    /// of the blocks the levels decided.
    fn settle(&mut self, settling: &mut Settling, first: bool) {
        let found = self.infer_signs(settling, first);
        self.store_signs(&found, &mut settling.ends);
        settling.ends.blocks.extend(
            found
                .iter()
                .filter(|f| f.ends != 0)
                .map(|f| (f.block, f.ends)),
        );
    }

    /// The inference of [`Run::settle`], block by block in parallel: updates `masks`,
    /// `crossed` and `open`, and returns what it inferred where it inferred anything.
    fn infer_signs(&mut self, settling: &mut Settling, first: bool) -> Vec<Inferred> {
        let (store, blocks, centres) = (&self.store, &self.blocks, &self.centres);
        let (cells, reach) = (self.lattice.cells(), &*settling.reach);
        let first = first.then_some((&self.decided, &self.known[..]));
        blocks
            .par_iter()
            .zip(
                self.masks
                    .par_iter_mut()
                    .zip(settling.crossed.par_iter_mut()),
            )
            .zip(settling.open.par_iter_mut())
            .enumerate()
            .with_min_len(256)
            .filter_map(|(i, ((&o, (m, x)), open))| {
                if *m == 0 {
                    return None;
                }
                // Before any leaf is settled, the store holds only the levels' values, which the
                // blocks carry (`known`: the centre and two corners at most); after, the
                // states are read from the store.
                let values = first.map(|(_, known)| {
                    let v = known[i].block_points(&store.values, centres[i]);
                    debug_assert!(v.iter().all(|&(p, x)| {
                        let y = store.leaf_block_values(o, centres[i], cells)[p];
                        x.to_bits() == y.to_bits() || y.is_nan()
                    }));
                    v
                });
                let (mut neg, mut pos, mut inferred) = match &values {
                    Some(v) => v.iter().fold((0, 0, 0), |(n, p, i), &(q, x)| {
                        (n | ((x < 0.0) as u32) << q, p | ((x >= 0.0) as u32) << q, i)
                    }),
                    None => sign_masks(&store.leaf_block_states(o, centres[i], cells)),
                };
                let unknown = LEAF_POINTS[*m as usize] & !(neg | pos);
                let (mut n, mut p) = (0, 0);
                if unknown != 0 {
                    let (mut bn, mut bp) = match &values {
                        Some(v) => balls(v.iter().copied(), reach),
                        // (After the first settling, every point without a sign was evaluated.)
                        None => {
                            let v = store.leaf_block_values(o, centres[i], cells);
                            balls(set_bits(neg | pos).map(|q| (q, v[q])), reach)
                        }
                    };
                    if let Some((decided, _)) = first {
                        let (dn, dp) = decided.masks(o);
                        (bn, bp) = (bn | dn, bp | dp);
                    }
                    (n, p) = (unknown & bn & !bp, unknown & bp & !bn);
                    neg |= n;
                    pos |= p;
                    inferred |= n | p;
                }
                let mut need = 0;
                for d in set_bits(*m) {
                    let corners = LEAF_POINTS[1 << d];
                    if corners & !(neg | pos) == 0 {
                        *m &= !(1 << d);
                        if corners & neg != 0 && corners & pos != 0 {
                            *x |= 1 << d;
                            need |= unknown_edge_ends(neg, inferred, d);
                        }
                    }
                }
                *open = LEAF_POINTS[*m as usize] & !(neg | pos);
                (n | p | need != 0).then_some(Inferred {
                    block: i as u32,
                    negative: n,
                    positive: p,
                    ends: need,
                })
            })
            .collect()
    }

    /// Stores the signs `found` in the points' states, in parallel. Two blocks infer different
    /// signs for a point only where the premise fails; then the signs are stored again one
    /// block after another, the first sign kept (as it would be whatever the threads do), and
    /// the blocks that disagreed go to the `ends`' suspects.
    fn store_signs(&mut self, found: &[Inferred], ends: &mut Ends) {
        let blocks = &self.blocks;
        let store = &mut self.store;
        let mut state_owned = std::mem::take(&mut store.state);
        let agreed = {
            let (st, state) = (&*store, atomic_states(&mut state_owned));
            found.par_iter().with_min_len(256).all(|f| {
                let o = blocks[f.block as usize];
                let mut agreed = true;
                for (m, negative) in [(f.negative, true), (f.positive, false)] {
                    for (s, _) in st.block_slots(o, m) {
                        agreed &= state[s].infer(negative).is_negative() == negative;
                    }
                }
                agreed
            })
        };
        store.state = state_owned;
        if agreed {
            return;
        }
        // Every point inferred here was unknown before.
        for f in found {
            let slots: Vec<usize> = store
                .block_slots(blocks[f.block as usize], f.negative | f.positive)
                .map(|(s, _)| s)
                .collect();
            for s in slots {
                store.state[s] = PointState::UNKNOWN;
            }
        }
        for f in found {
            let o = blocks[f.block as usize];
            if !store.set_block_signs(o, f.negative, f.positive) {
                ends.disagreed = true;
                ends.suspects.blocks.push(o);
            }
        }
    }

    /// Evaluates the ends of the crossed leaves' crossed edges that have only an inferred sign
    /// (edge vertices need both values): first those in `ends`, which the settling listed.
    /// Should a value contradict its inferred sign, or two blocks have inferred different signs
    /// (the premise failing either way), cases change, and the crossed leaves (`crossed`: per
    /// block, its crossed children) are searched for crossed edges with an end still unknown,
    /// until none is left. Returns where the premise failed.
    fn evaluate_crossed_edge_ends(&mut self, crossed: &[u8], ends: Ends) -> Result<Suspects> {
        let (lattice, blocks, centres) = (self.lattice, &self.blocks, &self.centres);
        let cells = lattice.cells();
        let store = &mut self.store;
        let (mut ends, mut disagreed, mut suspects) = (ends.blocks, ends.disagreed, ends.suspects);
        while !ends.is_empty() || disagreed {
            let mut taken = Vec::new();
            let mut points = Vec::new();
            for (i, need) in ends {
                let o = blocks[i as usize];
                for q in set_bits(need) {
                    let p = block_offset(o, q);
                    let s = store.slot_mut(p);
                    // A point two blocks share is taken once (queued until evaluated below).
                    let state = store.state[s];
                    if state.is_inferred() {
                        store.state[s] = PointState::QUEUED;
                        taken.push((s, state.is_negative(), p));
                        points.push(lattice.point(p));
                    }
                }
            }
            let mut values = vec![0.0; points.len()];
            evaluate(self.field, &points, &mut values, self.settings.common.batch)?;
            self.stats.evaluations += points.len() as u64;
            store.check_room(values.len())?;
            let mut contradicted = false;
            for (&(s, negative, p), v) in taken.iter().zip(values) {
                if (v < 0.0) != negative {
                    contradicted = true;
                    suspects.points.push(p);
                }
                store.state[s] = PointState::of_value(v);
                store.slots[s] = store.values.len() as u32;
                store.values.push(v);
            }
            // Without contradictions, the cases are those the ends were listed for.
            if !contradicted && !std::mem::take(&mut disagreed) {
                break;
            }
            let store = &*store;
            ends = blocks
                .par_iter()
                .zip(crossed.par_iter())
                .enumerate()
                .filter_map(|(i, (&o, &x))| {
                    let (neg, _, inferred) =
                        sign_masks(&store.leaf_block_states(o, centres[i], cells));
                    let need = set_bits(x).fold(0, |n, d| n | unknown_edge_ends(neg, inferred, d));
                    (need != 0).then_some((i as u32, need))
                })
                .collect();
        }
        Ok(suspects)
    }
}

/// The block points whose sign is known (bit per point) from their states: (negative, zero or
/// positive, the signs inferred without a value).
#[inline]
pub(super) fn sign_masks(states: &[PointState; 27]) -> (u32, u32, u32) {
    let (mut neg, mut pos, mut inferred) = (0, 0, 0);
    for (p, &x) in states.iter().enumerate() {
        neg |= (x.is_negative() as u32) << p;
        pos |= (x.is_positive() as u32) << p;
        inferred |= (x.is_inferred() as u32) << p;
    }
    (neg, pos, inferred)
}

/// The ends of the crossed edges of leaf `d` whose values are not known, only their signs
/// (bits of block points: `neg` the negative ones, `inferred` those with a sign only).
#[inline]
pub(super) fn unknown_edge_ends(neg: u32, inferred: u32, d: usize) -> u32 {
    let (mut negative, mut only_sign) = (0, 0);
    for (k, &p) in LEAF_CORNERS[d].iter().enumerate() {
        negative |= (((neg >> p) & 1) as usize) << k;
        only_sign |= (((inferred >> p) & 1) as u8) << k;
    }
    set_bits(CROSSED_EDGE_ENDS[negative] & only_sign)
        .fold(0, |need, k| need | 1 << LEAF_CORNERS[d][k])
}

/// `CROSSED_EDGE_ENDS[c]`: the corners of a cell with case `c` (bit k set: corner k negative)
/// that end a crossed edge (one whose ends differ in sign).
const CROSSED_EDGE_ENDS: [u8; 256] = {
    let mut t = [0; 256];
    let mut c = 0;
    while c < 256 {
        let mut e = 0;
        while e < 12 {
            let [a, b] = EDGES[e];
            if (c >> a) & 1 != (c >> b) & 1 {
                t[c] |= 1 << a | 1 << b;
            }
            e += 1;
        }
        c += 1;
    }
    t
};
