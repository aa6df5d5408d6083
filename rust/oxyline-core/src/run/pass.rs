//! One pass of a run: settings → plan → initial state → cycle loop → outcome.

use super::adaptive::{Adaptive, Scouted};
use super::checkpoint::{Checkpoints, Snapshot};
use super::coupling::{Species, State};
use super::cycle::Cycles;
use super::explicit::Explicit;
use super::mean_flow::MeanAbs;
use super::outcome::Outcome;
use super::plan::Plan;
use super::recorder::{OutputSink, Recorder};
use super::settings::RunSettings;
use crate::circuit::Dae;
use crate::error::Result;
use crate::integrate::steady::SteadyCache;
use crate::transport::{Formulation, Transport};

/// One pass: settings → plan → initial state → cycle loop → outcome. `mean` collects the
/// cycle-mean |Q| of a flow-only first pass; `scouted`, that pass's scout of an
/// error-controlled run (see `Scouted`). `checkpoints` saves snapshots at cycle ends and,
/// with a snapshot to resume from, starts there instead of at the initial state.
#[allow(clippy::too_many_arguments)]
pub(super) fn run(
    dae: &Dae,
    steady: &mut SteadyCache<'_>,
    s: &RunSettings,
    mut transport: Option<&mut Transport>,
    mean: Option<&mut MeanAbs>,
    scouted: Option<Scouted>,
    sink: Option<&mut OutputSink<'_>>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
    mut checkpoints: Option<&mut Checkpoints<'_>>,
) -> Result<Outcome> {
    s.validate(dae)?;
    if s.adaptive().is_some() && checkpoints.is_some() {
        return Err(crate::error::Error::model(
            "simulation",
            "checkpoints need a fixed step: give dt instead of rtol to checkpoint a run",
        ));
    }
    if !s.svzerod.is_empty() && checkpoints.is_some() {
        // the derived columns and cycle means start at the run's start, which a snapshot
        // does not carry
        return Err(crate::error::Error::model(
            "simulation",
            "svZeroDSolver's output conventions (svzerod) cannot be checkpointed",
        ));
    }
    // the load's freed pages (the parsed model, the assembly's rows) handed back before the
    // setup's transients (steady start, factorisation) are allocated on top of them: a large
    // run's peak resident set is its setup's, not its steps' (see `heap`)
    super::heap::release_free_pages(dae.n);
    let mut plan = Plan::new(dae, steady, s, transport.as_deref_mut(), progress)?;

    let resume = checkpoints.as_deref_mut().and_then(|c| c.resume.take());
    let (mut y, yd) = match &resume {
        Some(r) => resume_state(r, dae, plan.dt)?,
        None => plan.initial_state(steady, s)?,
    };
    if mean.is_none() {
        // the last pass (a first pass's coupled run starts from the same state) has its start
        steady.release();
        // (its factors handed back before the integrator's are made)
        super::heap::release_free_pages(dae.n);
    }
    let quasi = transport
        .as_deref()
        .is_some_and(|t| t.formulation() == Formulation::TlQuasisteady);
    // explicit (RK4) transport in the flow's own stages; implicit transport after each step.
    // A resumed run's state is not made consistent again (it is the state the run had).
    // (the copy only for a resumed run: it is one more state vector, 20 B per segment)
    let mut start = if resume.is_some() {
        y.clone()
    } else {
        Vec::new()
    };
    let y_start = if resume.is_some() { &mut start } else { &mut y };
    let mut flow = plan.flow(s, y_start, transport.is_some() && !quasi)?;
    if resume.is_none() && s.adaptive().is_none() {
        // a fixed-step run's one factorisation of a linear circuit, made before the species'
        // and the output's state exist: its values (~80 B per segment) are gone before they
        // are allocated, instead of adding to them at the first step (a large tree's peak)
        flow.integrator().factor_ahead(0.0, &y)?;
    }
    // the steady start's and the factorisation's freed values handed back before the species'
    // state, the cycle loop and the output's rows are allocated
    super::heap::release_free_pages(dae.n);
    let (species, initial_stored) = match transport {
        Some(tr) => {
            // per-segment species columns nobody records are not computed
            tr.set_recorded_columns(s.species_columns.as_deref());
            let level = flow.integrator().alpha_f();
            let split_implicit = !plan.use_rk4 && plan.explicit.is_none();
            let (sp, stored) = Species::start(tr, &y, plan.dt, level, split_implicit)?;
            (Some(sp), stored)
        }
        None => (None, Vec::new()),
    };
    let layout = species
        .as_ref()
        .map(|sp| (sp.tr.species_names().len(), sp.tr.columns_per_species()));
    let columns = s.species_columns.as_deref();
    let unwritten = species
        .as_ref()
        .map_or((0, 0), |sp| sp.tr.unwritten_columns());
    let mut rec = Recorder::new(&s.probes, layout, columns, initial_stored, sink)?
        .with_extra_columns(s.svzerod.extra_columns(s.probes.len()))
        .with_unwritten_species_columns(unwritten);
    if !s.output_all_cycles && mean.is_none() {
        // last-cycle output: one cycle's rows and the row at its start
        rec.reserve_rows(plan.steps_per_cycle / plan.stride + 1)?;
    }
    let state = State {
        dae,
        flow,
        species,
        y,
        yd,
        dt: plan.dt,
    };
    let method = plan.method_name();
    let mut cycles = Cycles::new(s, state, rec, mean, plan.steps_per_cycle, plan.stride);
    match (s.adaptive(), plan.explicit) {
        (Some(tol), Some(ceiling)) => cycles.explicit = Some(Explicit::new(dae, tol, s, ceiling)),
        (tol, _) => {
            cycles.adaptive =
                tol.map(|tol| Adaptive::new(dae, tol, s.method.rho_inf(), s.period, s.output_every))
        }
    }
    if let Some(tol) = s.adaptive() {
        cycles.events = super::events::Events::new(dae, &cycles.state.y, tol);
    }
    // (a run with valves takes no scout pass: see `Adaptive::scout`)
    if cycles.adaptive.is_some() && cycles.events.is_none() {
        let st = &cycles.state;
        if let Some(ad) = scouted.and_then(|sc| sc.seeded(&st.y, &st.yd)) {
            cycles.adaptive = Some(ad);
        }
    }
    cycles.start_svzerod(!plan.use_rk4);
    if let Some(r) = &resume {
        cycles.restore(r)?;
    }
    let error = cycles.run(progress, checkpoints);
    Ok(Outcome::of(cycles, method, plan.stability, error))
}

/// The (y, ẏ) of a snapshot, checked against the model and the planned step.
fn resume_state(r: &Snapshot, dae: &Dae, dt: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    let bad = |what: String| Err(crate::error::Error::model("checkpoint", what));
    if r.y.len() != dae.n || r.yd.len() != dae.n {
        return bad(format!(
            "the flow state has {} unknowns, this model's has {}: the checkpoint is of another model",
            r.y.len(),
            dae.n
        ));
    }
    if r.dt.to_bits() != dt.to_bits() {
        return bad(format!(
            "it was written with the time step {:e} s, this run's is {dt:e} s: the model or the \
             settings changed",
            r.dt
        ));
    }
    Ok((r.y.clone(), r.yd.clone()))
}
