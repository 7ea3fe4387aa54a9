//! Two pieces of work at once, one on another thread: what lets the element
//! use both cores of a small machine on one frame (the denoising beside the
//! network, the two halves of a frame or of the denoising's areas side by side).

use std::sync::{Mutex, OnceLock};

/// The threads `beside` hands work to, started at its first call and kept:
/// starting a thread for each piece of work cost about 0.1 ms here (`cargo run
/// --release --example paste_speed`), and a frame splits its work three or
/// four times. One a core, at most [`MOST_THREADS`], whatever
/// `RAYON_NUM_THREADS` says (the host's setting for its own work). Shared by
/// every element in the process, as the cores are. `None` where no thread
/// could be started: the work then runs on the calling thread from then on.
fn pool() -> Option<&'static rayon::ThreadPool> {
    static POOL: OnceLock<Option<rayon::ThreadPool>> = OnceLock::new();
    POOL.get_or_init(|| {
        let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
        rayon::ThreadPoolBuilder::new()
            .num_threads(cores.min(MOST_THREADS))
            .thread_name(|i| format!("lsydrelight-beside-{i}"))
            .build()
            .ok()
    })
    .as_ref()
}

/// Most threads the pool keeps: a split is two halves, so a few instances'
/// splits at once use this many, and a large machine's hundred cores are not
/// each given a thread.
const MOST_THREADS: usize = 8;

/// Runs `other` on another thread while `here` runs on this one, and returns
/// both results: for work of a fraction of a millisecond (halves of a frame),
/// which a kept thread of [`pool`] takes as soon as one is free. Where no thread can be
/// started (the system is out of them), `other` runs here after `here`:
/// slower, never lost. A panic in `other` carries on in this thread, as if it
/// had run here.
pub fn beside<A: Send, B>(other: impl FnOnce() -> A + Send, here: impl FnOnce() -> B) -> (A, B) {
    let Some(pool) = pool() else {
        let here = here();
        return (other(), here);
    };
    let mut done = None;
    let here = pool.in_place_scope(|scope| {
        scope.spawn(|_| done = Some(other()));
        here()
    });
    (done.expect("the scope ran the work"), here)
}

/// [`beside`] on a thread started for `other`: for work of milliseconds
/// that itself splits (the denoising beside the network). A kept thread that
/// waits for its own halves keeps looking for work meanwhile, and took time
/// from the network beside it (`benchmark --stages`, 720p); a thread of its own
/// sleeps while it waits.
pub fn beside_long<A: Send, B>(
    other: impl FnOnce() -> A + Send,
    here: impl FnOnce() -> B,
) -> (A, B) {
    // Held where both threads can reach it, so that a thread that fails to
    // start leaves the work here to run.
    let slot = Mutex::new(Some(other));
    let take = || {
        slot.lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .take()
    };
    std::thread::scope(|scope| {
        let spawned = std::thread::Builder::new()
            .name("lsydrelight-beside".into())
            .spawn_scoped(scope, || take().map(|work| work()));
        let here = here();
        let other = match spawned.map(|thread| thread.join()) {
            Ok(Ok(Some(done))) => done,
            Ok(Err(panic)) => std::panic::resume_unwind(panic),
            Ok(Ok(None)) | Err(_) => take().expect("the work did not run")(),
        };
        (other, here)
    })
}

#[cfg(test)]
mod tests {
    use super::{beside, beside_long};

    #[test]
    fn both_run_and_the_other_on_another_thread() {
        let here = std::thread::current().id();
        let (other, mine) = beside(|| std::thread::current().id(), || 7);
        assert_ne!(other, here);
        assert_eq!(mine, 7);
        let (other, mine) = beside_long(|| std::thread::current().id(), || 8);
        assert_ne!(other, here);
        assert_eq!(mine, 8);
    }

    #[test]
    fn work_borrowing_the_caller_sees_its_data() {
        let mut left = vec![1, 2, 3];
        let mut right = vec![4, 5];
        beside(|| left.push(0), || right.clear());
        assert_eq!((&left, &right), (&vec![1, 2, 3, 0], &vec![]));
        beside_long(|| left.push(9), || right.push(6));
        assert_eq!((left, right), (vec![1, 2, 3, 0, 9], vec![6]));
    }

    #[test]
    fn work_split_again_on_the_other_thread_finishes() {
        // The denoising beside the network splits its own areas: both kinds nest.
        let ((a, b), c) = beside_long(|| beside(|| 1, || 2), || beside(|| 3, || 4));
        assert_eq!((a, b, c), (1, 2, (3, 4)));
        let (inner, outer) = beside(|| beside(|| 5, || 6), || 7);
        assert_eq!((inner, outer), ((5, 6), 7));
    }

    #[test]
    fn a_panic_on_the_other_thread_carries_on_here() {
        for long in [false, true] {
            let caught = std::panic::catch_unwind(|| {
                let other = || -> u8 { panic!("the other half failed") };
                if long {
                    beside_long(other, || 0).0
                } else {
                    beside(other, || 0).0
                }
            });
            let message = caught.expect_err("the panic was lost");
            assert_eq!(
                message.downcast_ref::<&str>(),
                Some(&"the other half failed"),
                "long {long}"
            );
        }
    }
}
