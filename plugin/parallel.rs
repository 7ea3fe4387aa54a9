//! Two pieces of work at once, one on another thread: what lets the element
//! use both cores of a small machine on one frame (the denoising beside the
//! network, the two halves of a frame or of the denoising's areas side by side).

use std::sync::OnceLock;

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
        rayon::ThreadPoolBuilder::new()
            .num_threads(cores().min(MOST_THREADS))
            .thread_name(|i| format!("lsydrelight-beside-{i}"))
            .build()
            .ok()
    })
    .as_ref()
}

/// The cores this process may use (2 where the system does not say).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get())
}

/// The network's threads where the user leaves the choice (`requested` 0):
/// with the denoising on, one, on the thread that runs the network, so that
/// the frame's work never runs on more threads than there are cores ([`alongside`]);
/// without it, the 2 of the earlier default.
pub fn network_threads(requested: usize, denoising: bool) -> usize {
    match requested {
        0 if denoising => 1,
        0 => 2,
        n => n,
    }
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

/// Runs `here` on one kept thread of [`pool`] and `other` on another, and
/// returns both results: for work of milliseconds whose `other` splits its own
/// work with [`beside`] (the denoising beside the network). Whichever thread is
/// free takes a half still waiting: the thread that ran `here` takes the
/// other's second half once `here` is done, so two cores stay busy with no more
/// threads running than there are (with `here` on one). Where no thread can be
/// started, both run here in turn. A panic in either carries on in this thread.
pub fn alongside<A: Send, B: Send>(
    other: impl FnOnce() -> A + Send,
    here: impl FnOnce() -> B + Send,
) -> (A, B) {
    let Some(pool) = pool() else {
        let here = here();
        return (other(), here);
    };
    let (here, other) = pool.install(|| rayon::join(here, other));
    (other, here)
}

#[cfg(test)]
mod tests {
    use std::sync::{Barrier, mpsc};

    use super::{MOST_THREADS, alongside, beside, cores, network_threads};

    #[test]
    fn the_network_runs_on_one_thread_beside_the_denoising_unless_asked_otherwise() {
        assert_eq!(network_threads(0, true), 1);
        assert_eq!(network_threads(0, false), 2);
        assert_eq!(network_threads(3, true), 3);
        assert_eq!(network_threads(1, false), 1);
    }

    #[test]
    fn the_thread_free_first_takes_the_half_still_waiting() {
        // `here` waits for `other` to start on another kept thread: two are needed.
        if cores() < 2 {
            return;
        }
        let id = || std::thread::current().id();
        let started = &Barrier::new(2);
        let (bottom_ran, bottom_done) = mpsc::channel();
        let ((bottom, top), here) = alongside(
            move || {
                beside(
                    || {
                        let me = id();
                        bottom_ran.send(()).unwrap();
                        me
                    },
                    move || {
                        started.wait();
                        // The top half outlasts `here`: it waits for the bottom.
                        bottom_done.recv().unwrap();
                        id()
                    },
                )
            },
            || {
                started.wait();
                id()
            },
        );
        assert_ne!(top, here, "`other` ran beside `here`");
        assert_ne!(bottom, top, "the halves ran side by side");
        if cores().min(MOST_THREADS) == 2 {
            assert_eq!(
                bottom, here,
                "the thread done with `here` took the waiting half"
            );
        }
    }

    #[test]
    fn both_run_and_the_other_on_another_thread() {
        let here = std::thread::current().id();
        let (other, mine) = beside(|| std::thread::current().id(), || 7);
        assert_ne!(other, here);
        assert_eq!(mine, 7);
        let (other, mine) = alongside(|| 8, || std::thread::current().id());
        assert_eq!(other, 8);
        assert_ne!(mine, here, "`here` runs on a kept thread too");
    }

    #[test]
    fn work_borrowing_the_caller_sees_its_data() {
        let mut left = vec![1, 2, 3];
        let mut right = vec![4, 5];
        beside(|| left.push(0), || right.clear());
        assert_eq!((&left, &right), (&vec![1, 2, 3, 0], &vec![]));
        alongside(|| left.push(9), || right.push(6));
        assert_eq!((left, right), (vec![1, 2, 3, 0, 9], vec![6]));
    }

    #[test]
    fn work_split_again_on_the_other_thread_finishes() {
        // The denoising beside the network splits its own areas: both kinds nest.
        let ((a, b), c) = alongside(|| beside(|| 1, || 2), || beside(|| 3, || 4));
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
                    alongside(other, || 0).0
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
