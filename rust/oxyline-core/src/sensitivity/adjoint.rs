//! Adjoint (reverse) sensitivities of the periodic state: the gradient of a linear functional
//! J = Σ_k Σ_j w_kj y_j(t_k) of the recorded signals over the periodic cycle with respect to
//! every parameter at once, in one backward sweep to the adjoint's own periodic state.
//!
//! A tangent step of `super` is (s, ṡ) ↦ (s + γΔt Δ, pred ṡ + Δ) with
//! Δ = K_k⁻¹ (src_k − c E ṡ − (F + J_k) s). Its transpose takes the adjoint (a, b) of the
//! step's end to that of its start: δ = γΔt a + b, u = K_k⁻ᵀ δ, a ← a − (F + J_k)ᵀ u,
//! b ← pred b − c E u; the step's source contributes u · src_k(p) to dJ/dp. The periodic
//! tangent (s_0 = s_T) makes the adjoint periodic too (the adjoint of the cycle's start feeds
//! its end): its fixed point is found by the tangents' Anderson iteration, until (a, b) at the
//! start of a cycle run from it repeats to `tol`, and that cycle's sums u · src_k(p) are the
//! gradient. The cost is a few cycles on the transposed factorisation, whatever the number
//! of parameters (each parameter's source touches a few rows: its dot products cost next to
//! nothing).

use super::*;

/// Gradients of functionals of the periodic cycle.
#[derive(Debug, Clone)]
pub struct PeriodicAdjoint {
    /// J of each functional at the periodic state.
    pub values: Vec<f64>,
    /// gradients[f * n_params + p]: dJ_f / d parameter p.
    pub gradients: Vec<f64>,
    /// The forward run's cycles (the recorded one included).
    pub cycles: usize,
    /// Backward cycles of each functional to its adjoint's periodic state.
    pub adjoint_cycles: Vec<usize>,
    /// The largest relative change between the last two cycle starts (forward or adjoint).
    pub periodic_change: f64,
}

/// Kᵀ of the cycle's steps: one factorisation for a linear circuit, else one per step.
struct Transposed {
    base: Vec<f64>,
    lu: SparseLu,
    varying: bool,
}

impl Transposed {
    fn of(pr: &Primal) -> Result<Transposed> {
        let dae = pr.dae;
        let stamps: Vec<(usize, usize)> = jacobian_stamps(dae)
            .into_iter()
            .map(|(i, j)| (j, i))
            .collect();
        let mut t = Transposed {
            base: pr.base_values(),
            lu: SparseLu::analyse(dae.n, &stamps)?,
            varying: pr.newton.is_some(),
        };
        if !t.varying {
            t.lu.factor(&t.base).map_err(|m| singular(0.0, &m))?;
        }
        Ok(t)
    }

    /// Kᵀ of step k, factorised when it varies along the cycle.
    fn at(&mut self, pr: &Primal, k: usize) -> Result<&SparseLu> {
        if self.varying {
            let vals = pr.step_values(&self.base, k);
            let t = k as f64 * pr.scheme.dt;
            self.lu.factor(&vals).map_err(|msg| singular(t, &msg))?;
        }
        Ok(&self.lu)
    }
}

/// The primal at the end of its periodic cycle, the parameters' sources, the signals (n_steps
/// × signals), the forward cycles run, the last cycle's change and its start state (y, ẏ).
type Recorded<'a> = (Primal<'a>, Vec<Source>, Vec<f64>, usize, f64, Vec<f64>);

/// The forward run to the periodic state, then its periodic cycle with every parameter's
/// source and the signals recorded: the primal, the sources and the signals (n_steps ×
/// signals), and the forward cycles run with the last cycle's change.
fn recorded_cycle<'a>(
    dae: &'a Dae,
    params: &[DaeTangent],
    signals: &[usize],
    set: &TangentSettings,
) -> Result<Recorded<'a>> {
    let ns = set.steps_per_cycle.max(1);
    let scheme = Scheme::new(set.rho_infty, set.period / ns as f64)?;
    let dt = scheme.dt;
    let mut pr = Primal::new(dae, scheme)?;
    let cycles = forward_to_periodic(&mut pr, ns, set)?;
    let mut sources: Vec<Source> = params.iter().map(|t| Source::of(dae, t, ns)).collect();
    let mut values = Vec::with_capacity(ns * signals.len());
    let start = pr.state();
    for k in 0..ns {
        pr.increment(k as f64 * dt)?;
        for src in &mut sources {
            src.capture(&pr, k as f64 * dt);
        }
        pr.record_slopes(k as f64 * dt);
        pr.advance();
        values.extend(signals.iter().map(|&u| pr.y[u]));
    }
    let kn = dae.n_nodes.min(dae.n);
    let change = relative_change(&start[..dae.n], &pr.y, kn, 1.0, pr.floor());
    Ok((pr, sources, values, cycles + 1, change, start))
}

/// The gradients of the functionals J_f = Σ_k Σ_j weights[(f n_steps + k) n_signals + j]
/// · signal j after step k of the periodic cycle, with respect to every parameter.
pub fn periodic_adjoint(
    dae: &Dae,
    params: &[DaeTangent],
    signals: &[usize],
    weights: &[f64],
    set: TangentSettings,
) -> Result<PeriodicAdjoint> {
    periodic_adjoint_with(dae, params, signals, |_, _| Ok(weights.to_vec()), set)
}

/// [`periodic_adjoint`] with the weights chosen from the periodic cycle itself:
/// `weights_of(times, values)` gets the step end times (Δt … T) and the recorded signals
/// (n_steps × signals) of the one primal run and returns the weights. An output whose
/// derivative depends on the cycle (a maximum's step, a foot's samples) is linearised there
/// without a second forward run to the periodic state.
pub fn periodic_adjoint_with<W>(
    dae: &Dae,
    params: &[DaeTangent],
    signals: &[usize],
    weights_of: W,
    set: TangentSettings,
) -> Result<PeriodicAdjoint>
where
    W: FnOnce(&[f64], &[f64]) -> Result<Vec<f64>>,
{
    periodic_adjoint_in(dae, params, signals, weights_of, set, None)
}

/// [`periodic_adjoint_with`] of a closed loop conserving `volume` (`super::volume`): the
/// bordered adjoint. With v the unit-volume periodic tangent and ℓ the volume row, the forward
/// fixed point has (I − Φ) x = b_p, ℓ·x = β_p; the adjoint solves (I − Φᵀ) μ = h − σ ℓ with
/// σ = h·v (J's response to a unit volume, from v's recorded cycle), μ·v = 0, and
/// dJ/dp = μ·b_p + (the cycle's direct part) + σ β_p.
pub fn periodic_adjoint_in<W>(
    dae: &Dae,
    params: &[DaeTangent],
    signals: &[usize],
    weights_of: W,
    set: TangentSettings,
    volume: Option<&ConservedVolume>,
) -> Result<PeriodicAdjoint>
where
    W: FnOnce(&[f64], &[f64]) -> Result<Vec<f64>>,
{
    set.check()?;
    let (ns, nsig) = (set.steps_per_cycle.max(1), signals.len());
    let block = ns * nsig;
    if block == 0 {
        return Err(Error::model(
            "adjoint",
            "no signals to take the gradient of",
        ));
    }
    let (pr, sources, values, cycles, change, start) = recorded_cycle(dae, params, signals, &set)?;
    let times: Vec<f64> = (1..=ns).map(|k| k as f64 * pr.scheme.dt).collect();
    let weights = weights_of(&times, &values)?;
    if weights.len() % block != 0 {
        return Err(Error::model(
            "adjoint",
            format!(
                "weights: expected a multiple of {ns} steps x {nsig} signals, got {}",
                weights.len()
            ),
        ));
    }
    let mut kt = Transposed::of(&pr)?;
    let neutral = match volume {
        Some(vol) => Some(Neutral::of(&pr, vol, params, signals, &set, &start)?),
        None => None,
    };
    let mut out = PeriodicAdjoint {
        values: Vec::new(),
        gradients: Vec::new(),
        cycles,
        adjoint_cycles: Vec::new(),
        periodic_change: change,
    };
    let scales: Vec<f64> = params.iter().map(|t| scale_of(t.value)).collect();
    for w in weights.chunks(block) {
        let value = w.iter().zip(&values).map(|(a, b)| a * b).sum::<f64>();
        out.values.push(value);
        let fun = Functional {
            w,
            value,
            scales: &scales,
        };
        let mode = neutral.as_ref().map(|nm| (nm, nm.sigma(w)));
        let (grad, n_cycles, change) = backward(&pr, &mut kt, &sources, signals, &fun, &set, mode)?;
        out.gradients.extend(grad);
        out.adjoint_cycles.push(n_cycles);
        out.periodic_change = out.periodic_change.max(change);
    }
    Ok(out)
}

/// A closed loop's neutral mode on the adjoint's side: ℓ, the unit-volume tangent v (its
/// cycle-start state and signals) and each parameter's volume row β_p.
struct Neutral {
    row: Vec<f64>,
    v: Vec<f64>,
    v_signals: Vec<f64>,
    betas: Vec<f64>,
}

impl Neutral {
    fn of(
        pr: &Primal,
        vol: &ConservedVolume,
        params: &[DaeTangent],
        signals: &[usize],
        set: &TangentSettings,
        start: &[f64],
    ) -> Result<Neutral> {
        let (v, v_signals) = unit_volume_tangent(pr, vol, signals, set)?;
        let hold = Hold::of(vol, pr, params, start);
        Ok(Neutral {
            row: vol.row(hold.k),
            v,
            v_signals,
            betas: hold.targets,
        })
    }

    /// σ = h·v: the functional's response to a unit volume.
    fn sigma(&self, w: &[f64]) -> f64 {
        w.iter().zip(&self.v_signals).map(|(a, b)| a * b).sum()
    }

    /// λ ← λ − σ ℓ (the adjoint's forcing made solvable).
    fn shift(&self, sigma: f64, lambda: &mut [f64]) {
        lambda
            .iter_mut()
            .zip(&self.row)
            .for_each(|(l, r)| *l -= sigma * r);
    }

    /// λ ← λ − (v·λ) ℓ: the adjoint's fixed point is set up to ℓ; hold v·λ = 0.
    fn project(&self, lambda: &mut [f64]) {
        let d: f64 = self.v.iter().zip(lambda.iter()).map(|(a, b)| a * b).sum();
        lambda
            .iter_mut()
            .zip(&self.row)
            .for_each(|(l, r)| *l -= d * r);
    }
}

/// One functional: its weights (n_steps × signals), its value, and the parameters' scales
/// (|p|, or 1 at zero) its gradient is judged on.
struct Functional<'f> {
    w: &'f [f64],
    value: f64,
    scales: &'f [f64],
}

impl Functional<'_> {
    /// The change between two cycles' gradients, p·dJ/dp (J's response to a 100 % change of
    /// p) relative to the larger of |J| and the largest such response: a functional that no
    /// parameter changes (a prescribed mean inflow) has an adjoint of rounding noise, whose own
    /// relative change never settles, but a gradient that does.
    fn gradient_change(&self, a: &[f64], b: &[f64]) -> f64 {
        let resp = |g: &[f64]| -> f64 {
            g.iter()
                .zip(self.scales)
                .fold(0.0f64, |m, (x, p)| m.max((x * p).abs()))
        };
        let diff = a
            .iter()
            .zip(b)
            .zip(self.scales)
            .fold(0.0f64, |m, ((x, y), p)| m.max(((x - y) * p).abs()));
        diff / self.value.abs().max(resp(b)).max(1e-300)
    }
}

/// Backward cycles of one functional to the adjoint's periodic state: the gradient of the
/// last cycle, the cycles run and the last change. The adjoint's cycle map λ ↦ Φᵀ λ + g is
/// affine like the tangents', so its fixed point is found by the same Anderson iteration
/// ([`Subspace`]), weighted by the first cycle's magnitudes per row group; the answer is
/// always that of a cycle actually run. Periodic: the adjoint repeats to `tol`, or the
/// gradient does between two cycles.
fn backward(
    pr: &Primal,
    kt: &mut Transposed,
    sources: &[Source],
    signals: &[usize],
    fun: &Functional,
    set: &TangentSettings,
    neutral: Option<(&Neutral, f64)>,
) -> Result<(Vec<f64>, usize, f64)> {
    let dae = pr.dae;
    let n = dae.n;
    let w = fun.w;
    let mut grad = vec![0.0; sources.len()];
    let mut x = vec![0.0; 2 * n];
    let mut g = x.clone();
    backward_cycle(pr, kt, sources, signals, w, &mut g, &mut grad)?;
    if let Some((nm, sigma)) = neutral {
        nm.shift(sigma, &mut g);
    }
    let mut r: Vec<f64> = g.iter().zip(&x).map(|(a, b)| a - b).collect();
    let mut change = adjoint_change(&x, &g, dae);
    let mut sub = Subspace::new(adjoint_weights(&g, dae), 256);
    let mut cycles = 1;
    let mut last = grad.clone();
    while cycles < set.max_cycles && change > set.tol {
        let mut xn = sub.next(&x, &r);
        if let Some((nm, _)) = neutral {
            nm.project(&mut xn);
        }
        g.clone_from(&xn);
        backward_cycle(pr, kt, sources, signals, w, &mut g, &mut grad)?;
        if let Some((nm, sigma)) = neutral {
            nm.shift(sigma, &mut g);
        }
        let rn: Vec<f64> = g.iter().zip(&xn).map(|(a, b)| a - b).collect();
        change = adjoint_change(&xn, &g, dae).min(fun.gradient_change(&last, &grad));
        last.clone_from(&grad);
        let dx = xn.iter().zip(&x).map(|(a, b)| a - b).collect();
        let df = rn.iter().zip(&r).map(|(a, b)| a - b).collect();
        sub.add(dx, df);
        (x, r) = (xn, rn);
        cycles += 1;
    }
    if let Some((nm, sigma)) = neutral {
        grad.iter_mut()
            .zip(&nm.betas)
            .for_each(|(g, b)| *g += sigma * b);
    }
    Ok((grad, cycles, change))
}

/// One backward cycle from the adjoint λ = (a, b) of the cycle's end, in place (to that of
/// its start), with the cycle's gradient written into `grad`.
fn backward_cycle(
    pr: &Primal,
    kt: &mut Transposed,
    sources: &[Source],
    signals: &[usize],
    w: &[f64],
    lambda: &mut [f64],
    grad: &mut [f64],
) -> Result<()> {
    let dae = pr.dae;
    let (n, nsig) = (dae.n, signals.len());
    let sc = &pr.scheme;
    let (gdt, pred) = (sc.gamma * sc.dt, (sc.gamma - 1.0) / sc.gamma);
    let (a, b) = lambda.split_at_mut(n);
    let mut u = vec![0.0; n];
    grad.iter_mut().for_each(|g| *g = 0.0);
    for k in (0..w.len() / nsig.max(1)).rev() {
        for (&s, wk) in signals.iter().zip(&w[k * nsig..(k + 1) * nsig]) {
            a[s] += wk;
        }
        // the transpose of the tangent's reset rows (s_i ← 0 at the step's end)
        for &i in pr.held(k) {
            a[i] = 0.0;
        }
        for ((ui, ai), bi) in u.iter_mut().zip(a.iter()).zip(b.iter()) {
            *ui = gdt * ai + bi;
        }
        if !kt.at(pr, k)?.solve_in_place(&mut u) {
            return Err(singular(k as f64 * sc.dt, "non-finite adjoint"));
        }
        pr.chain_uncombine(&mut u);
        for (g, src) in grad.iter_mut().zip(sources) {
            *g += src.dot(k, &u);
        }
        // a ← a − (F + J_k)ᵀ u, b ← pred b − c E u
        for (i, &ui) in u.iter().enumerate() {
            for q in dae.f.row(i) {
                a[dae.f.col[q] as usize] -= dae.f.val[q] * ui;
            }
        }
        pr.local_apply(k, &u, a, true);
        for ((bi, ui), ei) in b.iter_mut().zip(&u).zip(&dae.e) {
            *bi = pred * *bi - pr.c * ei * ui;
        }
        pr.chain_adjoint(k, &u, a, b);
    }
    Ok(())
}

/// The inner product's weights over (a, b): each row by the inverse square of its group's
/// magnitude in `lambda` (node rows and others, of a and of b), whose units differ.
fn adjoint_weights(lambda: &[f64], dae: &Dae) -> Vec<f64> {
    let (n, kn) = (dae.n, dae.n_nodes.min(dae.n));
    let group = |i: usize| (i >= n) as usize * 2 + (i % n >= kn) as usize;
    let mut scale = [1e-300f64; 4];
    for (i, v) in lambda.iter().enumerate() {
        scale[group(i)] = scale[group(i)].max(v.abs());
    }
    (0..2 * n)
        .map(|i| 1.0 / (scale[group(i)] * scale[group(i)]))
        .collect()
}

/// The change of the adjoint (a, b) over a cycle relative to its size, taken apart by row
/// group (node rows, other rows; of a and of b), whose units differ.
fn adjoint_change(start: &[f64], end: &[f64], dae: &Dae) -> f64 {
    let (n, kn) = (dae.n, dae.n_nodes.min(dae.n));
    let floor = [1e-300; 2];
    relative_change(&start[..n], &end[..n], kn, 1.0, floor).max(relative_change(
        &start[n..],
        &end[n..],
        kn,
        1.0,
        floor,
    ))
}
