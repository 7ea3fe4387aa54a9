//! `lsydrelight train`: one command from capture folders (`lsydrelight
//! capture`) to a personal model the element accepts. Seven stages, each
//! reported as it runs:
//!
//! 1. [`capture`]: read and check the capture folders;
//! 2. [`prepare`]: decode, follow and crop the face as the element does, attach
//!    the screen light of each frame, and write the trainer's session format;
//!    with a few [`rehearsal`] sessions of the simulator's dome beside them;
//! 3. keypoints and pairing; 4. training (fine-tuning the starter model, or
//!    from scratch; resumable); 5. export to the model contract: the trainer's
//!    Python stages ([`python`], `train/lsyd/personal.py`), then the contract
//!    check as the element makes it (the model loaded by the engine);
//! 6. evaluation on the held-out session and the model card; 7. the
//!    before/after sheet (Python again).
//!
//! Everything it works on stays in `MODEL_DIR/training`, so running the same
//! command again continues where it stopped.

mod capture;
mod prepare;
mod python;
mod rehearsal;

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::time::Instant;

use gstlsydrelight::engine::{Provider, runtime};
use gstlsydrelight::face::CropRule;
use gstlsydrelight::paths;

use crate::exit::{Failure, Status};
use crate::interrupt;
use crate::progress::Bars;
use python::{Ended, Trainer};

/// Train a personal model from capture folders: prepare, pair, fine-tune, export, check, evaluate
#[derive(clap::Args)]
#[command(
    override_usage = "lsydrelight train --capture DIR [--capture DIR ...] --out MODEL_DIR \
        [--from DIR | --scratch [--resolution N]] [--steps N] [--offset SECONDS] [--fps N] \
        [--device auto|cpu|cuda] [--threads N]",
    long_about = "Train a personal model from capture folders: prepare, pair, fine-tune, export, \
        check, evaluate.\n\n\
        Reads the folders `lsydrelight capture` wrote, finds and crops your face in every camera \
        frame exactly as the element will (its face detector, tracker and the model's crop rule), \
        pairs frames of the same pose under different screen light by facial keypoints, \
        fine-tunes the starter model (models/starter) on the pairs, exports the model folder, \
        loads it as the element does, and measures it on the held-out session (the one \
        `lsydrelight capture --held-out` marked; else the latest session, or the last 20 % of \
        the only one). MODEL_DIR then holds the model (model.json and its ONNX stages, for the \
        element's model-location), network.pt (to fine-tune further), metrics.json, a model \
        card README.md and sheet.png (held-out frames relit to the targets).\n\n\
        Safe to stop: Ctrl-C saves the training's checkpoint, and running the same command \
        again continues from it; what was prepared is kept in MODEL_DIR/training.",
    after_help = concat!(
        "Examples:
  lsydrelight train --capture ~/lightstage --out models/me
  lsydrelight train --capture monday/ --capture tuesday/ --out models/me --steps 3000
  lsydrelight train --capture ~/lightstage --out models/me --scratch --steps 20000 --device cuda

",
        crate::exit::codes_help!()
    )
)]
pub struct Args {
    /// A capture folder written by `lsydrelight capture`; repeat for several
    #[arg(long = "capture", value_name = "DIR", required = true)]
    captures: Vec<PathBuf>,

    /// The model folder to write (created; training state is kept in its `training` folder)
    #[arg(long, value_name = "MODEL_DIR")]
    out: PathBuf,

    /// The model to fine-tune: a folder with network.pt [default: models/starter]
    #[arg(long, value_name = "DIR", conflicts_with = "scratch")]
    from: Option<PathBuf>,

    /// Train from random weights instead of fine-tuning (needs far more data and steps)
    #[arg(long)]
    scratch: bool,

    /// With --scratch, the network's resolution: a multiple of 16
    #[arg(long, value_name = "N", requires = "scratch", default_value_t = 96,
          value_parser = resolution)]
    resolution: u32,

    /// Training steps (batches of 8 pairs). Fine-tuning on about a minute of capture, 100 beat
    /// 500 and 2000 (docs/training.md, "A simulated stranger through the tools"); more capture may want more
    #[arg(long, value_name = "N", default_value_t = 100,
          value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    steps: u32,

    /// Seconds by which the screen's content precedes its light on the face (display and camera
    /// latency), -10 to 10
    #[arg(long, value_name = "SECONDS", default_value_t = 0.0, allow_negative_numbers = true,
          value_parser = crate::relight::offset_seconds)]
    offset: f64,

    /// Camera frames kept a second, at most
    #[arg(long, value_name = "N", default_value_t = 10,
          value_parser = clap::value_parser!(u32).range(1..=120))]
    fps: u32,

    /// Where the network trains: auto (a GPU when there is one), cpu or cuda
    #[arg(long, value_name = "DEVICE", default_value = "auto",
          value_parser = ["auto", "cpu", "cuda"])]
    device: String,

    /// CPU threads for training and evaluation; 0 uses every core (fewer can be faster on a
    /// machine busy with other work)
    #[arg(long, value_name = "N", default_value_t = 0,
          value_parser = clap::value_parser!(u32).range(0..=256))]
    threads: u32,
}

fn resolution(s: &str) -> Result<u32, String> {
    let v: u32 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a whole number"))?;
    if (16..=512).contains(&v) && v.is_multiple_of(16) {
        Ok(v)
    } else {
        Err(format!("{v} is not a multiple of 16 from 16 to 512"))
    }
}

pub fn run(args: Args, quiet: bool) -> Status {
    match train(&args, quiet) {
        Ok(status) => status,
        Err(_) if interrupt::stop_requested() => {
            eprintln!("stopped; run the same command again to continue");
            Status::Interrupted
        }
        Err(f) => f.report(),
    }
}

/// The stages, each timed and reported.
struct Stages<'a> {
    bars: &'a Bars,
    times: Vec<(&'static str, f64)>,
}

impl Stages<'_> {
    fn run<T>(
        &mut self,
        number: usize,
        name: &'static str,
        body: impl FnOnce() -> Result<T, Failure>,
    ) -> Result<T, Failure> {
        self.bars.note(&format!("[{number}/7] {name}"));
        let started = Instant::now();
        let result = body()?;
        let seconds = started.elapsed().as_secs_f64();
        self.bars.note(&format!("      {name}: {seconds:.1} s"));
        self.times.push((name, seconds));
        Ok(result)
    }
}

/// A Python stage's end as a result: an interrupted stage ends the command.
fn finished(ended: Ended) -> Result<(), Failure> {
    match ended {
        Ended::Done => Ok(()),
        Ended::Interrupted => Err(Failure::new("stopped")),
    }
}

fn train(args: &Args, quiet: bool) -> Result<Status, Failure> {
    let checkout = checkout();
    let out = absolute(&args.out);
    if out.is_file() {
        return Err(Failure::usage(format!(
            "--out {}: is a file; name the model folder to write",
            out.display()
        )));
    }
    let init = match (&args.from, args.scratch) {
        (_, true) => None,
        (from, false) => {
            let dir = from
                .as_deref()
                .map_or_else(|| checkout.join("models/starter"), absolute);
            let network = dir.join("network.pt");
            if !network.is_file() {
                return Err(Failure::new(format!(
                    "--from {}: no network.pt there; pass the starter model's folder \
                     (models/starter, or a personal model to fine-tune further), or --scratch to \
                     train from random weights",
                    dir.display()
                )));
            }
            Some(network)
        }
    };
    let trainer = Trainer::find(&checkout, quiet, args.threads)?;
    let work = out.join("training");
    std::fs::create_dir_all(&work)
        .map_err(|e| Failure::new(format!("cannot create {}: {e}", work.display())))?;

    let bars = Bars::new(quiet);
    let mut stages = Stages {
        bars: &bars,
        times: Vec::new(),
    };
    let crop = CropRule::TRAINING;
    let captures = stages.run(1, "check the capture folders", || {
        let captures = capture::read(&args.captures)?;
        let held = match captures.held_out {
            capture::HeldOut::Session(i) => format!("session {}", captures.sessions[i].label),
            capture::HeldOut::TailOfOnly => format!(
                "the last {:.0} % of the only session",
                capture::HELD_OUT_SHARE * 100.0
            ),
        };
        bars.note(&format!(
            "      {} sessions; held out for evaluation: {held}",
            captures.sessions.len()
        ));
        Ok(captures)
    })?;
    let counts = stages.run(
        2,
        "prepare: find and crop the face, attach the light",
        || {
            let settings = prepare::Settings {
                offset: args.offset,
                fps: args.fps as f64,
                crop,
            };
            let counts = prepare::run(&captures, &work, settings, &bars)?;
            let rehearsed = rehearsal::write(&work.join("data/captures"))?;
            bars.note(&format!(
                "      and {rehearsed} rehearsal sessions of the simulator's dome, so that the model \
                 keeps lights from the side"
            ));
            Ok(counts)
        },
    )?;
    let (kept, held): (u64, u64) = counts
        .iter()
        .fold((0, 0), |(k, h), (_, c)| (k + c.kept, h + c.held_out));
    if kept - held < 2 || held < 2 {
        return Err(Failure::new(format!(
            "{} frames to train on and {} held out: too few; record longer sessions",
            kept - held,
            held
        )));
    }
    let work_arg = || -> Vec<OsString> { vec!["--work".into(), work.clone().into()] };
    stages.run(3, "keypoints and pairing", || {
        finished(trainer.run(&[vec!["keypoints".into()], work_arg()].concat())?)
    })?;
    stages.run(4, "training", || {
        let mut a: Vec<OsString> = vec!["train".into()];
        a.extend(work_arg());
        match &init {
            Some(network) => a.extend(["--init".into(), network.clone().into()]),
            None => a.extend(["--resolution".into(), args.resolution.to_string().into()]),
        }
        a.extend([
            "--steps".into(),
            args.steps.to_string().into(),
            "--device".into(),
            args.device.clone().into(),
        ]);
        finished(trainer.run(&a)?)
    })?;
    stages.run(
        5,
        "export to the model contract, and load it as the element does",
        || {
            let mut a: Vec<OsString> = vec!["export".into()];
            a.extend(work_arg());
            a.extend(["--out".into(), out.clone().into()]);
            finished(trainer.run(&a)?)?;
            check_model(&out, crop, &bars)
        },
    )?;
    // The held-out stages: the model relit to the shipped targets.
    let on_model = |stage: &str| -> Vec<OsString> {
        let mut a: Vec<OsString> = vec![stage.into()];
        a.extend(work_arg());
        a.extend([
            "--model".into(),
            out.clone().into(),
            "--targets".into(),
            checkout.join("models/targets").into(),
        ]);
        a
    };
    stages.run(6, "evaluate on the held-out session; model card", || {
        let mut a = on_model("evaluate");
        a.extend(["--command".into(), command_line().into()]);
        finished(trainer.run(&a)?)
    })?;
    stages.run(7, "before/after sheet", || {
        finished(trainer.run(&on_model("sheet"))?)
    })?;
    let times: serde_json::Map<_, _> = stages
        .times
        .iter()
        .map(|(name, s)| {
            (
                name.to_string(),
                serde_json::json!((s * 10.0).round() / 10.0),
            )
        })
        .collect();
    let _ = std::fs::write(
        work.join("times.json"),
        serde_json::to_string_pretty(&times).unwrap_or_default() + "\n",
    );
    let total: f64 = stages.times.iter().map(|(_, s)| s).sum();
    bars.result(&format!(
        "{}: model ready in {total:.0} s (model.json, network.pt, metrics.json, README.md, sheet.png); \
         use it with model-location={} or lsydrelight relight --model {}",
        out.display(),
        out.display(),
        out.display()
    ));
    Ok(Status::Success)
}

/// The contract check the element makes when it loads a model: the manifest, and every
/// stage loaded by ONNX Runtime and checked against it; and the crop rule the frames were
/// cut with is the model's.
fn check_model(out: &Path, crop: CropRule, bars: &Bars) -> Result<(), Failure> {
    let env = runtime::environment(&paths::default_ort_library())
        .map_err(|e| Failure::new(e.to_string()))?;
    let (manifest, _) = runtime::load_model(env, out, 1, Provider::Cpu).map_err(|e| {
        Failure::new(format!(
            "{}: the exported model does not load in the element: {e}",
            out.display()
        ))
    })?;
    if manifest.crop.side != crop.side || manifest.crop.lift != crop.lift {
        return Err(Failure::new(format!(
            "{}: the model states the crop {:?}, but its frames were cut by {crop:?}",
            out.display(),
            manifest.crop
        )));
    }
    bars.note(&format!(
        "      the element loads {} ({} px, contract version {})",
        out.display(),
        manifest.resolution,
        manifest.version
    ));
    Ok(())
}

/// The checkout holding this program (`<checkout>/target/<profile>/lsydrelight`), found by
/// its trainer; else the current folder.
fn checkout() -> PathBuf {
    let has_trainer = |d: &Path| d.join("train/lsyd/personal.py").is_file();
    std::env::current_exe()
        .ok()
        .and_then(|exe| {
            exe.ancestors()
                .skip(1)
                .find(|d| has_trainer(d))
                .map(Path::to_path_buf)
        })
        .or_else(|| std::env::current_dir().ok())
        .unwrap_or_default()
}

fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The command as typed, for the model card.
fn command_line() -> String {
    let mut args = std::env::args();
    let program = args.next().map(|p| {
        Path::new(&p)
            .file_name()
            .map_or(p.clone(), |n| n.to_string_lossy().into_owned())
    });
    program
        .into_iter()
        .chain(args.map(|a| if a.contains(' ') { format!("'{a}'") } else { a }))
        .collect::<Vec<_>>()
        .join(" ")
}
