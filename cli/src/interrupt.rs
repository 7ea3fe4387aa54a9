//! Ctrl-C, and SIGTERM or SIGHUP (what `kill` and a closed terminal send). The
//! first asks every running job to stop cleanly: each sends end-of-stream
//! through its pipeline and waits for its files to be finished, so what was
//! done so far is kept and playable. A second aborts at once and removes the
//! unfinished outputs.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use crate::{exit, partial};

static PRESSES: AtomicUsize = AtomicUsize::new(0);

/// Process groups of the child programs running (the trainer's Python stages):
/// each runs in its own group, so a terminal's Ctrl-C reaches only this program,
/// which asks them to stop; an abort kills them.
static CHILDREN: Mutex<Vec<i32>> = Mutex::new(Vec::new());

fn children() -> std::sync::MutexGuard<'static, Vec<i32>> {
    CHILDREN.lock().unwrap_or_else(|e| e.into_inner())
}

/// A child program started in its own process group (`pgid`, its process id).
pub fn add_child(pgid: i32) {
    children().push(pgid);
}

/// The child has ended.
pub fn remove_child(pgid: i32) {
    children().retain(|&c| c != pgid);
}

pub fn install() {
    // ctrlc runs the handler on its own thread, not in the signal handler, so
    // it may lock, print and remove files.
    let installed = ctrlc::set_handler(|| {
        if PRESSES.fetch_add(1, Ordering::SeqCst) == 0 {
            eprintln!(
                "\nstopping: finishing cleanly and keeping what was done so far (Ctrl-C again to abort)"
            );
        } else {
            partial::remove_all();
            for &pgid in children().iter() {
                // SAFETY: kill takes no pointers; a group already gone is ESRCH, harmless.
                unsafe { libc::kill(-pgid, libc::SIGKILL) };
            }
            eprintln!("\naborted: unfinished outputs removed");
            // Not exit(): its atexit handlers tear down ONNX Runtime under the
            // pipelines' running threads, which then print errors or crash.
            // SAFETY: _exit takes no pointers and does not return.
            unsafe { libc::_exit(exit::Status::Interrupted as i32) }
        }
    });
    if let Err(e) = installed {
        eprintln!("warning: Ctrl-C will end the program without finishing its outputs: {e}");
    }
}

/// True once Ctrl-C was pressed: jobs running finish early, jobs waiting do not start.
pub fn stop_requested() -> bool {
    PRESSES.load(Ordering::SeqCst) > 0
}
