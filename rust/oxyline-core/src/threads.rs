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
    // restored also if `f` panics (the binding turns a panic into an error and goes on)
    struct Restore(Option<Option<Arc<ThreadPool>>>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let previous = self.0.take().flatten();
            POOL.with(|p| *p.borrow_mut() = previous);
        }
    }
    let _restore = Restore(Some(previous));
    Ok(f())
}

/// The run pool of this thread, if it has more than one thread.
pub fn pool() -> Option<Arc<ThreadPool>> {
    POOL.with(|p| p.borrow().clone())
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
