//! Times the crop (`sample_crop`), the denoising (`DetailDenoiser::apply`,
//! the element's `denoise`) and the paste (`LightingChange::apply`) on
//! synthetic frames, without GStreamer, as the element runs them: the default
//! full-height crop, the 96 px network and a feather of half the crop. The
//! full-height crop is what the crop rule (`face::CROP_SIDE`, 2.9 face
//! heights) gives a face a third of the frame's height, a person close to the
//! camera as in a call. The denoising, whose area grows with the crop's, is
//! timed again round a crop a third of the frame's height (`denoise, small
//! face`): a face a ninth of it, farther away; and so is the paste (`paste,
//! small face`), whose silhouette then runs down the frame under the face.
//!
//! ```text
//! cargo run --release --example paste_speed -- [--rounds 41] [--only "720p I420"]
//! ```
//!
//! `--only` keeps the sizes and formats whose row name contains it (as
//! printed: "720p I420", "Bgrx"), to time or profile one case alone.
//!
//! Beside them it times a monitor frame's light (`Light::from_frame`, read
//! from every pixel of a screen capture of that size and format, once a
//! monitor frame).
//!
//! Last, it times what the crop, the paste and the denoising pay to split
//! their work between two threads (`parallel::beside` with nothing to do),
//! which sets the sizes from which they split; and the colour tracking's read of
//! the face's colour from the network's input (`colour_tracking::face_colour`,
//! once a network run when the light is predicted), which does not depend on the
//! frame's size.
//!
//! Each round times every size and format once, in turn, so a busy machine
//! slows all of them alike rather than whichever ran at that moment. Every
//! frame is larger than the caches together or follows others that are, so the
//! times include reading the frame from memory, as a decoded frame would be.

use std::time::Instant;

use clap::Parser;

use gstlsydrelight::engine::colour_tracking::face_colour;
use gstlsydrelight::frame::{
    Crop, DetailDenoiser, FacePlace, LightingChange, OwnedFrame, PixelFormat, YuvMatrix,
    sample_crop,
};
use gstlsydrelight::light::Light;
use gstlsydrelight::parallel::beside;

const SIZES: [(&str, usize, usize); 4] = [
    ("480p", 854, 480),
    ("720p", 1280, 720),
    ("1080p", 1920, 1080),
    ("2160p", 3840, 2160),
];
const FORMATS: [PixelFormat; 3] = [PixelFormat::I420, PixelFormat::Nv12, PixelFormat::Bgrx];
/// The default network's resolution.
const RES: usize = 96;
/// A small face's crop, as a fraction of the frame's height.
const SMALL_FACE_CROP: f64 = 1.0 / 3.0;
/// The element's default feather, as a fraction of the crop.
const FEATHER: f64 = 0.5;
const MATRIX: YuvMatrix = YuvMatrix::BT709_LIMITED;

/// A frame of `format` full of noise (xorshift32: cheap, deterministic, no dependency).
fn noisy_frame(format: PixelFormat, width: usize, height: usize, seed: u32) -> OwnedFrame {
    let mut state = seed | 1;
    OwnedFrame::new(format, (width, height), 0, MATRIX, || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state >> 24) as u8
    })
}

struct Case {
    name: String,
    buffers: OwnedFrame,
    crop: Crop,
    feather: usize,
    change: LightingChange,
    denoiser: DetailDenoiser,
    small_crop: Crop,
    small_feather: usize,
    small_denoiser: DetailDenoiser,
    crop_ms: Vec<f64>,
    denoise_ms: Vec<f64>,
    small_ms: Vec<f64>,
    small_paste_ms: Vec<f64>,
    paste_ms: Vec<f64>,
    light_ms: Vec<f64>,
}

/// Times `parallel::beside` taken with nothing to do, per round.
const THREAD_STARTS: usize = 50;

/// "median (min-max)" of a list of times.
fn summary(times: &mut [f64]) -> String {
    times.sort_by(f64::total_cmp);
    format!(
        "{:7.3} ({:.3}-{:.3})",
        times[times.len() / 2],
        times[0],
        times[times.len() - 1]
    )
}

/// Times the crop, the denoising, the paste and a monitor frame's light on
/// synthetic frames of every size and format.
#[derive(Parser)]
struct Args {
    /// Rounds, each timing every case once.
    #[arg(long, default_value_t = 41)]
    rounds: usize,
    /// Only the cases whose name contains this ("720p I420", "Bgrx"); all by default.
    #[arg(long)]
    only: Option<String>,
}

fn main() {
    let Args { rounds, only } = Args::parse();
    let only = only.unwrap_or_default();

    let mut cases: Vec<Case> = Vec::new();
    let mut thread_ms = Vec::with_capacity(rounds * THREAD_STARTS);
    let mut face_colour_ms = Vec::with_capacity(rounds);
    let mut network_input = Vec::new();
    // Each case's frame is seeded by its place among all cases, so `--only`
    // times the same frames as a full run.
    let all = SIZES
        .iter()
        .flat_map(|size| FORMATS.map(|format| (*size, format)));
    for (seed, ((label, width, height), format)) in (7u32..).zip(all) {
        let name = format!("{label} {format:?}");
        if !name.contains(&only) {
            continue;
        }
        let buffers = noisy_frame(format, width, height, seed);
        let crop = Crop::centred(width, height, 0.5, 0.5, 1.0);
        let input = sample_crop(&buffers.frame(), crop, RES);
        network_input.clone_from(&input);
        // A plausible change: darker overall, brighter towards one side.
        let relit: Vec<f32> = input
            .iter()
            .enumerate()
            .map(|(i, v)| (0.8 * v + 0.2 * (i % RES) as f32 / RES as f32).min(1.0))
            .collect();
        let small_crop = Crop::centred(width, height, 0.5, 0.5, SMALL_FACE_CROP);
        cases.push(Case {
            name,
            change: LightingChange::new(&input, &relit, RES, FacePlace::default()),
            buffers,
            crop,
            feather: (FEATHER * crop.size as f64).round() as usize,
            denoiser: DetailDenoiser::default(),
            small_crop,
            small_feather: (FEATHER * small_crop.size as f64).round() as usize,
            small_denoiser: DetailDenoiser::default(),
            crop_ms: Vec::with_capacity(rounds),
            denoise_ms: Vec::with_capacity(rounds),
            small_ms: Vec::with_capacity(rounds),
            small_paste_ms: Vec::with_capacity(rounds),
            paste_ms: Vec::with_capacity(rounds),
            light_ms: Vec::with_capacity(rounds),
        });
    }

    for _ in 0..rounds {
        for case in &mut cases {
            let start = Instant::now();
            let image = sample_crop(&case.buffers.frame(), case.crop, RES);
            case.crop_ms.push(start.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(image);

            let start = Instant::now();
            case.denoiser
                .apply(&mut case.buffers.frame_mut(), case.crop, case.feather, 1.0);
            case.denoise_ms.push(start.elapsed().as_secs_f64() * 1e3);

            let start = Instant::now();
            case.small_denoiser.apply(
                &mut case.buffers.frame_mut(),
                case.small_crop,
                case.small_feather,
                1.0,
            );
            case.small_ms.push(start.elapsed().as_secs_f64() * 1e3);

            let start = Instant::now();
            case.change
                .apply(&mut case.buffers.frame_mut(), case.crop, case.feather);
            case.paste_ms.push(start.elapsed().as_secs_f64() * 1e3);

            let start = Instant::now();
            case.change.apply(
                &mut case.buffers.frame_mut(),
                case.small_crop,
                case.small_feather,
            );
            case.small_paste_ms
                .push(start.elapsed().as_secs_f64() * 1e3);

            let start = Instant::now();
            std::hint::black_box(Light::from_frame(&case.buffers.frame()));
            case.light_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        for _ in 0..THREAD_STARTS {
            let start = Instant::now();
            std::hint::black_box(beside(|| std::hint::black_box(1), || 2));
            thread_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
        if !network_input.is_empty() {
            let start = Instant::now();
            std::hint::black_box(face_colour(
                std::hint::black_box(&network_input),
                RES,
                FacePlace::default(),
            ));
            face_colour_ms.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }

    println!("{rounds} rounds, ms per frame: median (min-max)");
    println!(
        "{:<12} {:>26} {:>26} {:>26} {:>26} {:>26} {:>26}",
        "", "crop", "denoise", "paste", "denoise, small face", "paste, small face", "monitor light"
    );
    for case in &mut cases {
        println!(
            "{:<12} {:>26} {:>26} {:>26} {:>26} {:>26} {:>26}",
            case.name,
            summary(&mut case.crop_ms),
            summary(&mut case.denoise_ms),
            summary(&mut case.paste_ms),
            summary(&mut case.small_ms),
            summary(&mut case.small_paste_ms),
            summary(&mut case.light_ms)
        );
    }
    println!(
        "handing work to another thread and back (parallel::beside): {} ms",
        summary(&mut thread_ms)
    );
    if !face_colour_ms.is_empty() {
        println!(
            "the face's colour for the colour tracking, once a network run: {} ms",
            summary(&mut face_colour_ms)
        );
    }
}
