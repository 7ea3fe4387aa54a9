//! `--face DIR`: every recording in a folder, `--jobs` at a time, then one
//! line per file with its result, time and speed.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::job::{self, Files, Outcome, Output};
use super::{Args, Container, file_name};
use crate::exit::{Failure, Status};
use crate::progress::Bars;

/// The width of the results' first column, as wide as "not started".
const STATUS_COLUMN: usize = 11;

/// What counts as a recording in a folder; other files are left alone.
pub const RECORDING_EXTENSIONS: [&str; 9] = [
    "mp4", "mkv", "mov", "webm", "avi", "m4v", "ts", "y4m", "ogv",
];

pub fn run(args: &Args, quiet: bool) -> Result<Status, Failure> {
    for (flag, path) in [
        ("--screen", &args.screen),
        ("--predicted-monitor", &args.predicted_monitor),
        ("--out", &Some(args.out.clone())),
    ] {
        if path.as_deref().is_some_and(Path::is_file) {
            return Err(Failure::usage(format!(
                "{flag} names a file but --face a folder; pass a folder there too"
            )));
        }
    }
    let settings = super::settings(args)?;
    let jobs = plan(args)?;
    if jobs.is_empty() {
        return Err(Failure::new(format!(
            "--face {}: no recordings there (files ending .{})",
            args.face.display(),
            RECORDING_EXTENSIONS.join(", .")
        )));
    }

    let bars = Bars::new(quiet);
    let next = AtomicUsize::new(0);
    let outcomes: Mutex<Vec<Option<Outcome>>> = Mutex::new(jobs.iter().map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..(args.jobs as usize).min(jobs.len()) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some((name, files)) = jobs.get(i) else {
                        break;
                    };
                    let outcome = match files {
                        Ok(files) => job::run(&settings, files, &bars, &bars.add(name)),
                        Err(f) => Outcome::Failed(f.clone()),
                    };
                    outcomes.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(outcome);
                }
            });
        }
    });

    // Every slot was filled: each index was taken by exactly one worker.
    let outcomes: Vec<Outcome> = outcomes
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|o| o.unwrap_or(Outcome::NotStarted))
        .collect();
    for ((name, files), outcome) in jobs.iter().zip(&outcomes) {
        let line = outcome.line(name, files.as_ref().ok(), STATUS_COLUMN);
        match outcome {
            Outcome::Failed(_) => eprintln!("{line}"),
            _ => bars.result(&line),
        }
    }
    Ok(job::status(&outcomes))
}

/// Each recording of the folder, by name, with its files, or why it cannot run.
type Plan = Vec<(String, Result<Files, Failure>)>;

fn plan(args: &Args) -> Result<Plan, Failure> {
    let faces = recordings(&args.face)?;
    let screens = args.screen.as_deref().map(recordings).transpose()?;
    for dir in std::iter::once(&args.out).chain(&args.predicted_monitor) {
        if super::same_file(dir, &args.face) {
            return Err(Failure::usage(format!(
                "{} is the --face folder; write the outputs elsewhere, or they would replace the recordings",
                dir.display()
            )));
        }
        std::fs::create_dir_all(dir).map_err(|e| {
            Failure::new(format!("cannot create the folder {}: {e}", dir.display()))
        })?;
    }
    let mut plan: Plan = Vec::new();
    for face in faces {
        let files = files_of(args, &face, screens.as_deref());
        let clash = files.as_ref().ok().and_then(|f| {
            plan.iter()
                .any(|(_, other)| other.as_ref().is_ok_and(|o| o.out.path == f.out.path))
                .then(|| f.out.path.display().to_string())
        });
        let files = match clash {
            Some(out) => Err(Failure::new(format!(
                "another recording of the same name is written to {out}; rename one"
            ))),
            None => files,
        };
        plan.push((file_name(&face), files));
    }
    Ok(plan)
}

/// The files of the recording `face`: its screen recording is the one of the
/// same name in `--screen`, its outputs have its name in `--out` and
/// `--predicted-monitor`, with the container of `--container` or its own.
fn files_of(args: &Args, face: &Path, screens: Option<&[PathBuf]>) -> Result<Files, Failure> {
    let stem = face.file_stem().unwrap_or_default();
    let container = args
        .container
        .or_else(|| Container::of(face))
        .unwrap_or(Container::Mkv);
    // Not with_extension(): "call.v2" would lose its ".v2".
    let mut name = stem.to_os_string();
    name.push(".");
    name.push(container.extension());
    let output = |dir: &Path| Output {
        path: dir.join(&name),
        container,
    };
    let screen = match screens {
        None => None,
        Some(screens) => Some(
            screens
                .iter()
                .find(|s| s.file_stem() == Some(stem))
                .cloned()
                .ok_or_else(|| {
                    Failure::new(format!(
                        "no screen recording named {}.* in --screen {}",
                        stem.to_string_lossy(),
                        args.screen.as_deref().unwrap_or(Path::new("")).display()
                    ))
                })?,
        ),
    };
    Ok(Files {
        face: face.to_path_buf(),
        screen,
        target_video: args.target.as_deref().map(PathBuf::from),
        out: output(&args.out),
        predicted: args.predicted_monitor.as_deref().map(output),
    })
}

/// The recordings in a folder, by name.
fn recordings(dir: &Path) -> Result<Vec<PathBuf>, Failure> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| Failure::new(format!("cannot read the folder {}: {e}", dir.display())))?;
    let mut found: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            let hidden = p
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'));
            let known = p
                .extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| RECORDING_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
            p.is_file() && known && !hidden
        })
        .collect();
    found.sort();
    Ok(found)
}
