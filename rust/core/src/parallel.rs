//! Thread-count control: run work on a rayon pool of a chosen size (0 = all cores).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

fn pools() -> &'static Mutex<HashMap<usize, Arc<rayon::ThreadPool>>> {
    static POOLS: OnceLock<Mutex<HashMap<usize, Arc<rayon::ThreadPool>>>> = OnceLock::new();
    POOLS.get_or_init(|| Mutex::new(HashMap::new()))
}

/// Runs `f` with rayon's parallel iterators limited to `num_threads` threads
/// (0 = rayon's global pool, one thread per core). Pools are built once per size and reused.
pub fn with_threads<R: Send>(num_threads: usize, f: impl FnOnce() -> R + Send) -> R {
    if num_threads == 0 {
        return f();
    }
    let pool = {
        let mut map = pools().lock().unwrap_or_else(|e| e.into_inner());
        map.entry(num_threads)
            .or_insert_with(|| {
                Arc::new(
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(num_threads)
                        .thread_name(|i| format!("binpick-{i}"))
                        .build()
                        .expect("rayon pool"),
                )
            })
            .clone()
    };
    // The pool's threads do not see the caller's thread-locals: carry the call's cancel flag over.
    let token = crate::cancel::current();
    pool.install(move || crate::cancel::enter(token, f))
}
