//! Two pieces of work at once, one on another thread: what lets the element
//! use both cores of a small machine on one frame (the denoising beside the
//! network, the two halves of a frame or of the denoising's areas side by side).

use std::sync::Mutex;

/// Runs `other` on another thread while `here` runs on this one, and returns
/// both results. Where no thread can be started (the system is out of them),
/// `other` runs here after `here`: slower, never lost. A panic in `other`
/// carries on in this thread, as if it had run here.
pub fn beside<A: Send, B>(other: impl FnOnce() -> A + Send, here: impl FnOnce() -> B) -> (A, B) {
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
    use super::beside;

    #[test]
    fn both_run_and_the_other_on_another_thread() {
        let here = std::thread::current().id();
        let (other, mine) = beside(|| std::thread::current().id(), || 7);
        assert_ne!(other, here);
        assert_eq!(mine, 7);
    }

    #[test]
    fn work_borrowing_the_caller_sees_its_data() {
        let mut left = vec![1, 2, 3];
        let mut right = vec![4, 5];
        beside(|| left.push(0), || right.clear());
        assert_eq!((left, right), (vec![1, 2, 3, 0], vec![]));
    }
}
