//! Moving new vertices onto the zero set: batched Newton steps, and a line search along the
//! gradient with bisection where Newton fails.

use super::evaluator::Evaluator;
use super::settings::SubdivisionSettings;
use crate::error::Result;
use crate::field::Field;
use glam::DVec3;

/// Newton steps shorter than this multiple of the local edge length that fail to halve the
/// previous step are taken as the rounding noise of the field: the point has converged.
const NOISE_STEP: f64 = 1e-6;

/// A Newton step is taken without a confirming evaluation when the step after it, predicted from
/// quadratic convergence (`len³ / last²`), times this margin is below the tolerance.
const PREDICT_MARGIN: f64 = 10.0;

/// ... and when the step is at most this multiple of the local edge length, so that the gradient
/// of the last evaluation (kept for the normal) is taken that close to the final point.
const PREDICT_MAX_STEP: f64 = 1e-5;

/// What `project` did to a batch of points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Projection {
    /// Projected points.
    pub points: Vec<DVec3>,
    /// Newton evaluations per point.
    pub iterations: Vec<u32>,
    /// Points handed to the line-search fallback.
    pub fallbacks: usize,
    /// Indices of the points the fallback could not place either.
    pub not_converged: Vec<usize>,
    /// For points Newton placed: the value and gradient of its last evaluation (one final step
    /// away from the final point: shorter than the tolerance, or than `PREDICT_MAX_STEP` × the
    /// local edge length when accepted by prediction, and then with the value predicted at the
    /// final point); `None` for the fallback's points.
    pub last: Vec<Option<(f64, DVec3)>>,
}

#[derive(Clone, Copy, PartialEq)]
enum State {
    Moving,
    Done,
    Failed,
}

/// Moves every start point onto the zero set: Newton steps r ← r − f ∇f / |∇f|² (Jin eq. 10),
/// all still-moving points evaluated in one batched call per step. `scales[i]` is the local
/// edge length of point `i`, which sets the stopping tolerance, the longest step and how far the
/// point may go; `hints[i]` is a direction to search along when the gradient vanishes at the
/// start (e.g. the mean normal of the parent edge).
///
/// Points where Newton fails (vanishing gradient, too many steps, wandering too far) are searched
/// along the gradient line through their start point for the nearest sign change, then bisected.
pub(super) fn project<F: Field + ?Sized>(
    eval: &mut Evaluator<'_, F>,
    starts: &[DVec3],
    scales: &[f64],
    hints: &[DVec3],
    s: &SubdivisionSettings,
) -> Result<Projection> {
    let n = starts.len();
    let mut pos = starts.to_vec();
    let mut iterations = vec![0u32; n];
    let mut state = vec![State::Moving; n];
    // Value and gradient at the start point (for the fallback); best point seen.
    let mut f0 = vec![0.0; n];
    let mut g0 = vec![DVec3::ZERO; n];
    let mut best: Vec<(f64, DVec3)> = starts.iter().map(|&p| (f64::INFINITY, p)).collect();
    let mut last = vec![f64::INFINITY; n];
    // Gradient of the previous evaluation and the step taken from it (for the secant estimate of
    // the gradient at a point accepted by prediction).
    let mut prev: Vec<(DVec3, DVec3)> = vec![(DVec3::ZERO, DVec3::ZERO); n];
    let mut last_eval: Vec<Option<(f64, DVec3)>> = vec![None; n];
    let mut active: Vec<usize> = (0..n).collect();
    let mut pts: Vec<DVec3> = Vec::with_capacity(n);
    let mut vals = vec![0.0; n];
    let mut grads = vec![DVec3::ZERO; n];
    for step in 0..s.max_iterations {
        if active.is_empty() {
            break;
        }
        pts.clear();
        pts.extend(active.iter().map(|&i| pos[i]));
        let m = pts.len();
        eval.both(&pts, &mut vals[..m], &mut grads[..m])?;
        let mut next = Vec::with_capacity(m);
        for (k, &i) in active.iter().enumerate() {
            let (f, g) = (vals[k], grads[k]);
            iterations[i] += 1;
            if step == 0 {
                f0[i] = f;
                g0[i] = g;
            }
            if f.abs() < best[i].0 {
                best[i] = (f.abs(), pos[i]);
            }
            if f == 0.0 {
                state[i] = State::Done;
                last_eval[i] = Some((f, g));
                continue;
            }
            let g2 = g.length_squared();
            if !(g2 > 0.0 && g2.is_finite()) {
                state[i] = State::Failed;
                continue;
            }
            let mut d = g * (-f / g2);
            let len = d.length();
            let h = scales[i];
            if !len.is_finite() {
                state[i] = State::Failed;
                continue;
            }
            // Converged, or stalled at the rounding noise of f: a tiny step that is no longer
            // shrinking quadratically.
            if len <= s.tolerance * h || (len <= NOISE_STEP * h && len > 0.5 * last[i]) {
                if len < last[i] {
                    pos[i] += d;
                }
                state[i] = State::Done;
                last_eval[i] = Some((f, g));
                continue;
            }
            // Converging quadratically (the step at least halved): Newton's error after this step
            // is about the next step, C len² with C = len / last², so the step is taken and the
            // point accepted when that prediction, with a margin, is below the tolerance. This
            // saves the evaluation that would only confirm it. The value kept is the one predicted
            // at the final point alike, f (len / last)², and the gradient is carried over the step
            // by the secant of the previous one, g + (g − g_prev) (d·d_prev) / |d_prev|² (the two
            // steps are nearly parallel, both along the gradient), so that the normal stays that
            // of the final point to second order.
            if last[i].is_finite()
                && len <= 0.5 * last[i]
                && len <= PREDICT_MAX_STEP * h
                && PREDICT_MARGIN * len * (len / last[i]).powi(2) <= s.tolerance * h
            {
                pos[i] += d;
                state[i] = State::Done;
                let (gp, dp) = prev[i];
                let dd = dp.length_squared();
                let moved = g + (g - gp) * (d.dot(dp) / dd);
                let g_final = if dd > 0.0 && moved.is_finite() {
                    moved
                } else {
                    g
                };
                last_eval[i] = Some((f * (len / last[i]).powi(2), g_final));
                continue;
            }
            last[i] = len;
            if len > s.max_step * h {
                d *= s.max_step * h / len;
            }
            pos[i] += d;
            prev[i] = (g, d);
            if (pos[i] - starts[i]).length() > s.max_distance * h {
                state[i] = State::Failed;
            } else {
                next.push(i);
            }
        }
        // Progress: the points placed at this step.
        crate::cancel::advance(active.iter().filter(|&&i| state[i] == State::Done).count() as u64)?;
        active = next;
    }
    for &i in &active {
        state[i] = State::Failed;
    }

    // Fallback: nearest sign change along the gradient line through the start point.
    let failed: Vec<usize> = (0..n).filter(|&i| state[i] == State::Failed).collect();
    let mut not_converged = Vec::new();
    if !failed.is_empty() {
        let ns = s.search_samples as usize;
        let dirs: Vec<DVec3> = failed
            .iter()
            .map(|&i| {
                let g = g0[i].normalize_or_zero();
                if g != DVec3::ZERO {
                    g
                } else {
                    hints[i].normalize_or_zero()
                }
            })
            .collect();
        let t_of = |i: usize, j: usize| -> f64 {
            // Sample j in 0..2ns: first the + side outward, then the − side outward.
            let r = s.search_range * scales[i] * ((j % ns) + 1) as f64 / ns as f64;
            if j < ns {
                r
            } else {
                -r
            }
        };
        let mut probes = Vec::with_capacity(failed.len() * 2 * ns);
        for (k, &i) in failed.iter().enumerate() {
            for j in 0..2 * ns {
                probes.push(starts[i] + dirs[k] * t_of(i, j));
            }
        }
        let mut pv = vec![0.0; probes.len()];
        if dirs.iter().any(|d| *d != DVec3::ZERO) {
            eval.values(&probes, &mut pv)?;
        }
        // Brackets (lo, f_lo, hi, f_hi) in t.
        let mut brackets: Vec<(usize, f64, f64, f64, f64)> = Vec::new();
        for (k, &i) in failed.iter().enumerate() {
            if dirs[k] == DVec3::ZERO {
                not_converged.push(i);
                continue;
            }
            let mut found: Option<(f64, f64, f64, f64)> = None;
            for side in 0..2 {
                let (mut tp, mut fp) = (0.0, f0[i]);
                for j in 0..ns {
                    let jj = side * ns + j;
                    let (t, f) = (t_of(i, jj), pv[k * 2 * ns + jj]);
                    if f.abs() < best[i].0 {
                        best[i] = (f.abs(), starts[i] + dirs[k] * t);
                    }
                    if (f <= 0.0) != (fp <= 0.0) {
                        if found.is_none_or(|b| t.abs() < b.2.abs().max(b.0.abs())) {
                            found = Some((tp, fp, t, f));
                        }
                        break;
                    }
                    (tp, fp) = (t, f);
                }
            }
            match found {
                Some((a, fa, b, fb)) => brackets.push((k, a, fa, b, fb)),
                None => not_converged.push(i),
            }
        }
        // Bisection, all bracketed points per batched call.
        let mut open: Vec<usize> = (0..brackets.len()).collect();
        let mut mids = Vec::with_capacity(brackets.len());
        let mut mv = vec![0.0; brackets.len()];
        for _ in 0..200 {
            open.retain(|&b| {
                let (k, a, _, c, _) = brackets[b];
                (c - a).abs() > s.tolerance * scales[failed[k]]
            });
            if open.is_empty() {
                break;
            }
            mids.clear();
            mids.extend(open.iter().map(|&b| {
                let (k, a, _, c, _) = brackets[b];
                starts[failed[k]] + dirs[k] * (0.5 * (a + c))
            }));
            eval.values(&mids, &mut mv[..open.len()])?;
            for (q, &b) in open.iter().enumerate() {
                let (_, a, fa, c, fc) = &mut brackets[b];
                let (t, f) = (0.5 * (*a + *c), mv[q]);
                if f == 0.0 {
                    (*a, *fa, *c, *fc) = (t, f, t, f);
                } else if (f <= 0.0) == (*fa <= 0.0) {
                    (*a, *fa) = (t, f);
                } else {
                    (*c, *fc) = (t, f);
                }
            }
        }
        for &(k, a, fa, c, fc) in &brackets {
            let i = failed[k];
            let t = if fa.abs() <= fc.abs() { a } else { c };
            pos[i] = starts[i] + dirs[k] * t;
        }
        for &i in &not_converged {
            pos[i] = best[i].1;
        }
    }
    // Progress: the fallback's points, placed or left at their best point.
    crate::cancel::advance(failed.len() as u64)?;
    Ok(Projection {
        points: pos,
        iterations,
        fallbacks: failed.len(),
        not_converged,
        last: last_eval,
    })
}
