//! `lsydrelight relight`: relights recorded calls offline. The face video is
//! decoded, relit and encoded to H.264; audio and every other stream are kept
//! as they are (parsed and remuxed, never re-encoded).

mod diagnose;
mod folder;
mod graph;
mod job;
mod target;

use std::path::{Path, PathBuf};

use crate::exit::{Failure, Status};
use crate::progress::Bars;
use graph::Container;
use job::{Files, Outcome, Output, Settings};
use target::{Target, ViewArgs};

/// Relight recorded calls: the face video relit to a target light; audio and other streams kept as they are
#[derive(clap::Args)]
#[command(
    override_usage = "lsydrelight relight --face FILE [--screen FILE [--offset SECONDS]] \
        [--target PRESET|FILE [--fov DEG] [--yaw DEG] [--pitch DEG] [--exposure STOPS]] \
        [--model DIR] [--quality N] [--predicted-monitor FILE] --out FILE\n       \
        lsydrelight relight --face DIR [--screen DIR [--offset SECONDS]] [--target PRESET|FILE] \
        [--model DIR] [--quality N] [--predicted-monitor DIR] [--container FORMAT] [--jobs N] --out DIR",
    long_about = "Relight recorded calls: the face video relit to a target light; audio and \
        other streams kept as they are.\n\n\
        The face video is decoded (any container and codec GStreamer's decodebin reads), relit \
        and encoded to H.264 with x264 in MP4 or MKV, as the output's extension says. Audio, \
        subtitles and any further stream are parsed and remuxed, never re-encoded. The output is \
        written under a temporary name beside the final one (.NAME.PID.part) and renamed when \
        complete, so a failed run never leaves a partial file under the final name.\n\n\
        With --face DIR, every recording in the folder (.mp4 .mkv .mov .webm .avi .m4v .ts .y4m \
        .ogv) is relit into --out DIR under its own name, --jobs at a time, and a line per file \
        says how it went; --screen and --predicted-monitor then name folders too, and a screen \
        recording is the one with the same name before its extension.",
    after_help = concat!(
        "Examples:
  lsydrelight relight --face call.mp4 --out relit.mp4
  lsydrelight relight --face examples/data/call/face.mp4 --screen examples/data/call/monitor.mp4 \\
      --target models/targets/sunset.png --predicted-monitor monitor.mp4 --out relit.mp4
  lsydrelight relight --face call.mp4 --target warm-key-left --out relit.mp4
  lsydrelight relight --face call.mp4 --target room.exr --yaw 90 --exposure -1 --out relit.mp4
  lsydrelight relight --face call.mp4 --target background.mp4 --out relit.mp4
  lsydrelight relight --face calls/ --out relit/ --jobs 2

",
        crate::exit::codes_help!()
    )
)]
pub struct Args {
    /// The face recording, or a folder of them
    #[arg(long, value_name = "FILE|DIR")]
    face: PathBuf,

    /// The screen recording of the same call: what the monitor showed (a folder with --face DIR).
    /// Without it the light on the face is predicted from the face
    #[arg(long, value_name = "FILE|DIR")]
    screen: Option<PathBuf>,

    /// Seconds by which the screen content precedes its light on the face (display and camera
    /// latency), -10 to 10
    #[arg(
        long,
        value_name = "SECONDS",
        requires = "screen",
        default_value_t = 0.0,
        allow_negative_numbers = true,
        value_parser = offset_seconds
    )]
    offset: f64,

    /// The target light [default: models/targets/studio.png]: a preset (soft-front,
    /// warm-key-left, cool-key-right, rim, sunset, office, overcast, candle, neon), a PNG of
    /// monitor content, an environment map (.hdr, .exr; a PNG/JPEG panorama with --fov, --yaw,
    /// --pitch or --exposure), or a video whose frames light the face as they play (a virtual
    /// background; its last frame stays when it ends)
    #[arg(long, value_name = "PRESET|FILE")]
    target: Option<String>,

    /// Degrees of the environment map the monitor shows across (half as many up and down) [default: 180]
    #[arg(long, value_name = "DEG", value_parser = clap::value_parser!(f64))]
    fov: Option<f64>,

    /// Degrees the viewer turns to the right in the environment map [default: 0]
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    yaw: Option<f64>,

    /// Degrees the view tilts up in the environment map [default: 0]
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pitch: Option<f64>,

    /// Stops by which the environment map is brightened before it is clipped to the
    /// monitor's range [default: 0]
    #[arg(long, value_name = "STOPS", allow_negative_numbers = true)]
    exposure: Option<f64>,

    /// The model's folder [default: models/starter, trained on many people]
    #[arg(long, value_name = "DIR")]
    model: Option<PathBuf>,

    /// Video quality: x264's constant quality, 0 (lossless) to 50; lower is better and larger,
    /// about 18 looks lossless
    #[arg(long, value_name = "N", default_value_t = 21,
          value_parser = clap::value_parser!(u32).range(0..=50))]
    quality: u32,

    /// Also write the predicted monitor light (256x128 video) here (a folder with --face DIR)
    #[arg(long, value_name = "FILE|DIR")]
    predicted_monitor: Option<PathBuf>,

    /// The relit recording: .mp4 or .mkv (a folder with --face DIR)
    #[arg(long, value_name = "FILE|DIR")]
    out: PathBuf,

    /// With --face DIR, how many recordings to relight at once
    #[arg(short, long, value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u32).range(1..=64))]
    jobs: u32,

    /// With --face DIR, the outputs' container [default: the input's when .mp4 or .mkv, else mkv]
    #[arg(long, value_name = "FORMAT")]
    container: Option<Container>,
}

pub(crate) fn offset_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if (-10.0..=10.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is outside -10 to 10 seconds"))
    }
}

pub fn run(args: Args, quiet: bool) -> Status {
    let run = if args.face.is_dir() {
        folder::run(&args, quiet)
    } else {
        single(&args, quiet)
    };
    run.unwrap_or_else(|f| f.report())
}

/// `--face FILE`: one recording, its result in a line.
fn single(args: &Args, quiet: bool) -> Result<Status, Failure> {
    let files = single_files(args)?;
    let settings = settings(args)?;
    let bars = Bars::new(quiet);
    let name = file_name(&files.face);
    let bar = bars.add(&name);
    let outcome = job::run(&settings, &files, &bars, &bar);
    let line = outcome.line(&name, Some(&files), 0);
    match &outcome {
        Outcome::Failed(f) => return Err(f.clone()),
        Outcome::Done { .. } => bars.result(&line),
        Outcome::Stopped { .. } | Outcome::NotStarted => eprintln!("{line}"),
    }
    Ok(job::status(&[outcome]))
}

/// The files of `--face FILE`: the command line first, then the files it names.
fn single_files(args: &Args) -> Result<Files, Failure> {
    if args.container.is_some() {
        return Err(Failure::usage(
            "--container is for --face DIR; with a file, --out's extension names the container",
        ));
    }
    if args.screen.as_deref().is_some_and(Path::is_dir) {
        return Err(Failure::usage(
            "--screen names a folder but --face a file; pass the screen recording's file",
        ));
    }
    let out = output("--out", &args.out)?;
    let predicted = match &args.predicted_monitor {
        Some(p) => Some(output("--predicted-monitor", p)?),
        None => None,
    };
    check_inputs(args)?;
    for o in std::iter::once(&out).chain(&predicted) {
        if same_file(&o.path, &args.face) {
            return Err(Failure::usage(format!(
                "{} is the face recording; write the output elsewhere",
                o.path.display()
            )));
        }
        let folder = o.path.parent().filter(|p| !p.as_os_str().is_empty());
        // A typo in the folder should not create folders.
        if let Some(f) = folder
            && !f.is_dir()
        {
            return Err(Failure::new(format!(
                "cannot write {}: the folder {} does not exist",
                o.path.display(),
                f.display()
            )));
        }
    }
    Ok(Files {
        face: args.face.clone(),
        screen: args.screen.clone(),
        target_video: args.target.as_deref().map(PathBuf::from),
        out,
        predicted,
    })
}

/// An output file named on the command line: not a folder, with a container's extension.
fn output(flag: &str, path: &Path) -> Result<Output, Failure> {
    let output = (!path.is_dir())
        .then(|| Output::new(path.to_path_buf()))
        .flatten();
    output.ok_or_else(|| {
        Failure::usage(format!(
            "{flag} {}: name the output file, .mp4 or .mkv (its extension names the container)",
            path.display()
        ))
    })
}

/// The face and screen recordings exist.
fn check_inputs(args: &Args) -> Result<(), Failure> {
    for (flag, path) in [
        ("--face", Some(&args.face)),
        ("--screen", args.screen.as_ref()),
    ] {
        if let Some(p) = path
            && !p.exists()
        {
            return Err(Failure::new(format!(
                "{flag} {}: no such file or folder",
                p.display()
            )));
        }
    }
    Ok(())
}

/// What every recording is relit with, checked before anything runs.
fn settings(args: &Args) -> Result<Settings, Failure> {
    check_model(args.model.as_deref())?;
    let view = ViewArgs {
        fov: args.fov,
        yaw: args.yaw,
        pitch: args.pitch,
        exposure: args.exposure,
    };
    for (flag, value, range) in [
        ("--fov", view.fov, 1.0..=360.0),
        ("--yaw", view.yaw, -360.0..=360.0),
        ("--pitch", view.pitch, -90.0..=90.0),
        ("--exposure", view.exposure, -20.0..=20.0),
    ] {
        if let Some(v) = value
            && !range.contains(&v)
        {
            return Err(Failure::usage(format!(
                "{flag} {v} is outside {} to {}",
                range.start(),
                range.end()
            )));
        }
    }
    let target = match &args.target {
        Some(t) => Some(Target::parse(t, view)?),
        None if view.fov.is_some()
            || view.yaw.is_some()
            || view.pitch.is_some()
            || view.exposure.is_some() =>
        {
            return Err(Failure::usage(
                "--fov, --yaw, --pitch and --exposure need an environment map as --target",
            ));
        }
        None => None,
    };
    Ok(Settings {
        model: args.model.clone(),
        target,
        monitor_offset_ns: (args.offset * 1e9).round() as i64,
        quality: args.quality,
    })
}

fn check_model(model: Option<&Path>) -> Result<(), Failure> {
    let dir = model.map_or_else(gstlsydrelight::paths::default_model, Path::to_path_buf);
    if dir.join("model.json").is_file() {
        return Ok(());
    }
    Err(Failure::new(match model {
        Some(_) => format!(
            "--model {}: no model.json there; pass a model folder (model.json and its ONNX \
             stages, as lsyd.export writes them; the shipped ones are models/starter and models/default)",
            dir.display()
        ),
        None => format!(
            "no model at {}; run from the lsydrelight checkout or pass --model DIR",
            dir.display()
        ),
    }))
}

fn same_file(a: &Path, b: &Path) -> bool {
    matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .unwrap_or(path.as_os_str())
        .to_string_lossy()
        .into_owned()
}
