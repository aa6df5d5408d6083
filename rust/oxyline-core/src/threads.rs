//! The threads of one run (`threads=`): a rayon pool that the large loops of a step (the tree
//! elimination, the step's residual and update) split their work over, while the run itself —
//! its time loop, callbacks and output — stays on the calling thread (so that Ctrl-C and the
//! Python callbacks behave as in a serial run).
//!
//! Each run's pool is set for the calling thread only ([`with_threads`]); code that runs without
//! one (Rust callers, ensemble variants, which already fill the cores) runs serially: the same
//! code path as before threads existed. The parallel loops use fixed partitions and the serial
//! order of every sum, so a run's results are bit-identical for any number of threads.

use crate::error::{Error, Result};
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

thread_local! {
    /// The pool of the run on this thread (None: serial).
    static POOL: RefCell<Option<Arc<ThreadPool>>> = const { RefCell::new(None) };
}

/// One pool per thread count, built at the first run that asks for it and kept (building one
/// starts its threads; a test suite or a study runs many small simulations).
fn pool_of(threads: usize) -> Result<Arc<ThreadPool>> {
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<ThreadPool>>>> = OnceLock::new();
    let mut pools = POOLS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(p) = pools.get(&threads) {
        return Ok(p.clone());
    }
    let pool = ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("oxyline-run-{i}"))
        // a step's serial parts run on a pool thread too (`in_pool`): the stack of a main
        // thread, not the 2 MiB default of spawned ones
        .stack_size(STACK_BYTES)
        .build()
        .map_err(|e| Error::Resource {
            what: "simulation: threads".to_owned(),
            bytes: 0,
            message: format!(
                "cannot start {threads} threads ({e}); set threads = 1 or free resources"
            ),
        })?;
    let pool = Arc::new(pool);
    pools.insert(threads, pool.clone());
    Ok(pool)
}

/// The stack of a run pool's thread (the usual main thread's; reserved, touched as used).
const STACK_BYTES: usize = 8 << 20;

/// Most threads a run may ask for.
pub const MAX_THREADS: usize = 4096;
const MAX_THREADS_PLUS_ONE: usize = MAX_THREADS + 1;

/// The number of threads a run uses for `threads` (None: every core the process may use).
pub fn resolve(threads: Option<usize>) -> usize {
    threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// Run `f` with the run pool of `threads` threads set for this thread (None: every core;
/// 1: no pool, the serial code path). The previous setting is restored afterwards.
pub fn with_threads<R>(threads: Option<usize>, f: impl FnOnce() -> R) -> Result<R> {
    if let Some(t @ (0 | MAX_THREADS_PLUS_ONE..)) = threads {
        // more threads than any machine's cores only costs their stacks (a billion would be
        // started one by one for minutes before failing)
        return Err(Error::model(
            "simulation",
            format!("threads must be an integer from 1 to {MAX_THREADS}, got {t}"),
        ));
    }
    let n = resolve(threads);
    let pool = match (n > 1, threads) {
        (false, _) => None,
        (true, Some(_)) => Some(pool_of(n)?),
        // the default (every core) is a speed choice, not the user's: where the system cannot
        // start the threads (address space or process limits), the run is serial, with the
        // same bits
        (true, None) => pool_of(n).ok(),
    };
    let previous = POOL.with(|p| p.replace(pool));
    // restored also if `f` panics
    let _restore = Restore(Some(previous));
    Ok(f())
}

/// The run pool of this thread, if it has more than one thread.
pub fn pool() -> Option<Arc<ThreadPool>> {
    POOL.with(|p| p.borrow().clone())
}

/// `f` run as one entry of the run's pool, with that pool set for the pool thread that runs
/// it, so that every split pass inside `f` starts from a pool thread (rayon runs a pool
/// thread's `install` of its own pool in place and hands its tasks to the idle threads):
/// the calling thread wakes the pool and sleeps once for all of `f` instead of once per pass.
/// The passes take the same paths and partitions as from the calling thread, so the results
/// are the same bits. Without a pool (one thread), or already on a pool thread, `f` runs here.
///
/// `f` need not be `Send`: it runs on one pool thread while the calling thread blocks until
/// it returns (a scoped thread), and the run's state it touches has no tie to a thread (no
/// `Rc`, no callbacks into Python; the thread-locals are per-thread scratch, and this pool).
pub fn in_pool<R>(f: impl FnOnce() -> R) -> R {
    let Some(pool) = pool() else {
        return f();
    };
    if pool.current_thread_index().is_some() {
        return f();
    }
    struct Crossing<T>(T);
    // SAFETY: see the doc above: one thread at a time touches `f`, its captures and `R`,
    // the calling thread blocked in `install` meanwhile
    unsafe impl<T> Send for Crossing<T> {}
    let (run, inner) = (Crossing(f), Crossing(pool.clone()));
    let out = pool.install(move || {
        let (Crossing(f), Crossing(pool)) = (run, inner);
        let previous = POOL.with(|p| p.replace(Some(pool)));
        let _restore = Restore(Some(previous));
        Crossing(f())
    });
    out.0
}

/// The least work of a step (unknowns, or transport cells times species) for which
/// [`in_pool_for`] crosses to a pool thread: the smallest splits of a step's passes (the tree
/// elimination's and the transport's, `PARALLEL_MIN`; the element-wise passes' at 2 `CHUNK`)
/// start at 2^14 elements, so below it every pass of the step runs serially wherever it is
/// called from, and a crossing only wakes a pool thread, puts the calling thread to sleep and
/// leaves the woken thread spinning for work afterwards (rayon's idle rounds), all process
/// CPU and none of it work: an error-controlled step crosses three times.
pub const CROSSING_MIN: usize = 1 << 14;

/// [`in_pool`] for a step of `work` elements (see [`CROSSING_MIN`]): below it `f` runs on the
/// calling thread, with the run's pool still set for any pass inside that would split. The
/// same passes with the same partitions either way: the same bits.
pub fn in_pool_for<R>(work: usize, f: impl FnOnce() -> R) -> R {
    if work < CROSSING_MIN {
        return f();
    }
    in_pool(f)
}

/// Puts a thread's previous run pool back when dropped (also when the run panics: the
/// binding turns a panic into an error and goes on).
struct Restore(Option<Option<Arc<ThreadPool>>>);

impl Drop for Restore {
    fn drop(&mut self) {
        let previous = self.0.take().flatten();
        POOL.with(|p| *p.borrow_mut() = previous);
    }
}

/// Elements per task of the run loop's element-wise passes ([`max_over`], [`for_chunks`]),
/// and half the least length for which they are split at all.
pub const CHUNK: usize = 1 << 15;

/// The run's pool if a pass over `len` elements is worth splitting over it.
fn pool_for(len: usize) -> Option<Arc<ThreadPool>> {
    if len >= 2 * CHUNK { pool() } else { None }
}

/// The largest of `f` over the ranges of `CHUNK` elements of `0..len` (on the run's threads
/// for a long pass): the same number on any number of threads (a maximum is exact).
pub fn max_over(len: usize, f: impl Fn(std::ops::Range<usize>) -> f64 + Sync + Send) -> f64 {
    use rayon::prelude::*;
    let range = |c: usize| c * CHUNK..((c + 1) * CHUNK).min(len);
    let chunks = len.div_ceil(CHUNK);
    match pool_for(len) {
        Some(pool) => pool.install(|| {
            (0..chunks)
                .into_par_iter()
                .map(|c| f(range(c)))
                .reduce(|| 0.0, f64::max)
        }),
        None => (0..chunks).map(|c| f(range(c))).fold(0.0, f64::max),
    }
}

/// `f(first, chunk)` for the chunks of `CHUNK` elements of `v` (on the run's threads for a
/// long pass); each element is written by one call, so the result is the same on any number
/// of threads.
pub fn for_chunks<T: Send>(v: &mut [T], f: impl Fn(usize, &mut [T]) + Sync + Send) {
    use rayon::prelude::*;
    match pool_for(v.len()) {
        Some(pool) => pool.install(|| {
            v.par_chunks_mut(CHUNK)
                .enumerate()
                .for_each(|(c, s)| f(c * CHUNK, s))
        }),
        None => v
            .chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(c, s)| f(c * CHUNK, s)),
    }
}

/// `f` on the ranges of `CHUNK` elements of `0..len` (on the run's threads for a long pass),
/// for passes in which each element is written by the call of its range alone (through the
/// caller's shared slices), so the result is the same on any number of threads.
pub fn for_ranges(len: usize, f: impl Fn(std::ops::Range<usize>) + Sync + Send) {
    for_ranges_of(len, CHUNK, f);
}

/// [`for_ranges`] with ranges of `chunk` elements (split from `2 chunk` elements on).
pub fn for_ranges_of(len: usize, chunk: usize, f: impl Fn(std::ops::Range<usize>) + Sync + Send) {
    use rayon::prelude::*;
    let range = |c: usize| c * chunk..((c + 1) * chunk).min(len);
    let chunks = len.div_ceil(chunk);
    match pool().filter(|_| len >= 2 * chunk) {
        Some(pool) => pool.install(|| (0..chunks).into_par_iter().for_each(|c| f(range(c)))),
        None => (0..chunks).for_each(|c| f(range(c))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ i² over 0..len by a split pass (each element written by its chunk's call), then
    /// summed in order.
    fn chunked_sum_of_squares(len: usize) -> u64 {
        let mut values = vec![0u64; len];
        for_chunks(&mut values, |first, v| {
            for (i, x) in v.iter_mut().enumerate() {
                *x = ((first + i) as u64).pow(2);
            }
        });
        values.iter().sum()
    }

    #[test]
    fn a_phase_runs_on_one_pool_thread_with_the_pool_set() {
        let len = 5 * CHUNK + 17;
        // the closed form n(n-1)(2n-1)/6 of Σ_{i<n} i²
        let n = len as u64;
        let truth = n * (n - 1) * (2 * n - 1) / 6;
        with_threads(Some(2), || {
            assert!(pool().is_some());
            let outside = std::thread::current().id();
            let (inside, index, has_pool, sum) = in_pool(|| {
                let sum = chunked_sum_of_squares(len);
                let has = pool().is_some();
                (
                    std::thread::current().id(),
                    rayon::current_thread_index(),
                    has,
                    sum,
                )
            });
            assert_ne!(inside, outside, "the phase runs on a pool thread");
            assert!(index.is_some());
            assert!(has_pool, "the passes inside see the run's pool");
            assert_eq!(sum, truth);
            // a nested phase runs in place; the calling thread keeps its pool afterwards
            let nested = in_pool(|| in_pool(rayon::current_thread_index));
            assert!(nested.is_some());
            assert!(pool().is_some());
        })
        .unwrap();
    }

    #[test]
    fn a_small_steps_phase_stays_on_the_calling_thread_and_a_large_ones_crosses() {
        with_threads(Some(2), || {
            let here = std::thread::current().id();
            let small = in_pool_for(CROSSING_MIN - 1, || {
                (std::thread::current().id(), pool().is_some())
            });
            assert_eq!(small, (here, true), "serial here, the pool still set");
            let large = in_pool_for(CROSSING_MIN, || std::thread::current().id());
            assert_ne!(large, here);
        })
        .unwrap();
    }

    #[test]
    fn without_a_pool_a_phase_runs_on_the_calling_thread() {
        with_threads(Some(1), || {
            let here = std::thread::current().id();
            let (there, index) =
                in_pool(|| (std::thread::current().id(), rayon::current_thread_index()));
            assert_eq!(there, here);
            assert!(index.is_none());
        })
        .unwrap();
    }

    #[test]
    fn a_panic_in_a_phase_reaches_the_caller_and_leaves_the_pool_thread_serial() {
        with_threads(Some(2), || {
            let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                in_pool(|| panic!("a failing step"))
            }));
            assert!(caught.is_err());
            assert!(pool().is_some(), "the calling thread keeps its pool");
            // the pool's threads have no run pool of their own outside a phase
            let p = pool().unwrap();
            let seen: Vec<bool> = p.broadcast(|_| super::pool().is_none());
            assert!(seen.iter().all(|&none| none));
        })
        .unwrap();
    }
}
