//! Running the trainer's Python stages (`train/lsyd/personal.py`) as child
//! programs: their progress (tqdm bars) and messages go straight to this
//! program's terminal. Each child runs in its own process group, so Ctrl-C
//! reaches this program only; it passes the first on as SIGINT (the trainer
//! then saves a checkpoint and exits), and an abort kills the group.

use std::ffi::OsString;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::exit::Failure;
use crate::interrupt;

/// How a stage ended, when it did not fail.
#[derive(Debug, PartialEq, Eq)]
pub enum Ended {
    Done,
    /// Stopped by Ctrl-C; what it saved is kept.
    Interrupted,
}

pub struct Trainer {
    python: PathBuf,
    /// The checkout's `train` folder, which holds the `lsyd` package.
    package_root: PathBuf,
    quiet: bool,
    /// CPU threads for PyTorch and ONNX Runtime (0: one per core).
    threads: u32,
}

impl Trainer {
    /// The trainer of the checkout this program runs from (or the current folder's),
    /// with the checkout's Python (`.venv/bin/python`) or `LSYDRELIGHT_PYTHON`.
    pub fn find(checkout: &Path, quiet: bool, threads: u32) -> Result<Trainer, Failure> {
        let package_root = checkout.join("train");
        if !package_root.join("lsyd/personal.py").is_file() {
            return Err(Failure::new(format!(
                "the trainer (train/lsyd) is not in {}; run lsydrelight train from the lsydrelight checkout",
                checkout.display()
            )));
        }
        let python = std::env::var_os("LSYDRELIGHT_PYTHON")
            .map(PathBuf::from)
            .unwrap_or_else(|| checkout.join(".venv/bin/python"));
        if !python.exists() {
            return Err(Failure::new(format!(
                "no Python for the trainer at {}; run scripts/test.sh once (it installs the pinned \
                 stack of train/requirements.txt into .venv), or point LSYDRELIGHT_PYTHON at a Python \
                 that has it",
                python.display()
            )));
        }
        Ok(Trainer {
            python,
            package_root,
            quiet,
            threads,
        })
    }

    /// Runs `python -m lsyd.personal <args>` to its end.
    pub fn run(&self, args: &[OsString]) -> Result<Ended, Failure> {
        let mut command = Command::new(&self.python);
        command
            .arg("-m")
            .arg("lsyd.personal")
            .args(args)
            .env("PYTHONPATH", &self.package_root)
            .env("PYTHONUNBUFFERED", "1")
            .stdin(Stdio::null())
            .process_group(0);
        if self.quiet {
            command.stdout(Stdio::null()).env("TQDM_DISABLE", "1");
        }
        if self.threads > 0 {
            command.env("OMP_NUM_THREADS", self.threads.to_string());
        }
        // PyTorch's threads otherwise spin while they wait for each other: on a machine
        // busy with anything else, a 2-thread training step then took 13 times as long
        // (measured at 32 px under a load of 12 on 2 cores; 2 times with passive waiting).
        if std::env::var_os("OMP_WAIT_POLICY").is_none() {
            command.env("OMP_WAIT_POLICY", "PASSIVE");
        }
        let stage = args
            .first()
            .map(|a| a.to_string_lossy().into_owned())
            .unwrap_or_default();
        let mut child = command.spawn().map_err(|e| {
            Failure::new(format!(
                "cannot start the trainer's Python {}: {e}",
                self.python.display()
            ))
        })?;
        let pgid = child.id() as i32;
        interrupt::add_child(pgid);
        let mut forwarded = false;
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break Ok(status),
                Ok(None) => {}
                Err(e) => break Err(e),
            }
            if interrupt::stop_requested() && !forwarded {
                // SAFETY: kill takes no pointers.
                unsafe { libc::kill(pgid, libc::SIGINT) };
                forwarded = true;
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        interrupt::remove_child(pgid);
        let status = status.map_err(|e| Failure::new(format!("the {stage} stage: {e}")))?;
        if status.success() {
            Ok(Ended::Done)
        } else if interrupt::stop_requested()
            || status.code() == Some(130)
            || status.signal() == Some(libc::SIGINT)
        {
            Ok(Ended::Interrupted)
        } else {
            Err(Failure::new(format!(
                "the {stage} stage failed ({status}); the trainer's message above says why"
            )))
        }
    }
}
