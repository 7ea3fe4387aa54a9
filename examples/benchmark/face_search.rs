//! `--face-search`: what looking for small faces costs the face detector at
//! 1080p, against the whole frame alone (the detector before it looked
//! further), in interleaved rounds.
//!
//! Three frames: a grey wall with nobody (the scan of tiles runs), the
//! portrait with its face a tenth of the height off centre (found by the
//! scan, then looked for round where it was), and the portrait with its face
//! at 45% of the height, a webcam's framing (found in the whole frame, still
//! small there, so looked at again round itself). A face is found first, as
//! the tracker that follows it would have it (the scan may take a few
//! detections to reach it: the "nobody" row is what they cost). Each is then
//! detected `REPEATS` times a round; the table gives the median milliseconds a
//! detection and, at the tracker's default interval, the mean a frame.

use std::fmt::Write as _;
use std::time::Instant;

use gstlsydrelight::engine::environment;
use gstlsydrelight::face::{FaceDetector, TrackerSettings};
use gstlsydrelight::frame::Frame;
use gstlsydrelight::paths::{default_face_detector, default_ort_library};
use lsydrelight_testkit::checkout;
use lsydrelight_testkit::footage::small_portrait_1080p;

/// Detections timed per frame and round.
const REPEATS: usize = 20;
/// Detections a face must be found within before it is timed.
const FIND_WITHIN: usize = 64;

fn median_min_max(mut v: Vec<f64>) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0], v[v.len() - 1])
}

pub(crate) fn face_search(rounds: usize) -> Result<String, String> {
    let media = checkout().join("target/real-media");
    let env = environment(&default_ort_library()).map_err(|e| e.to_string())?;
    let detector =
        || FaceDetector::new(env, &default_face_detector(), 1).map_err(|e| e.to_string());
    let (small, ..) = small_portrait_1080p(&media, 0.10, [0.8, 0.3])?;
    let (large, ..) = small_portrait_1080p(&media, 0.45, [0.5, 0.45])?;
    let mut nobody = small.clone();
    nobody.data.fill(96);
    // Each frame, and whether it shows a face.
    let frames = [
        ("nobody", &nobody, false),
        ("a face 10% of the height", &small, true),
        ("a face 45% of the height", &large, true),
    ];
    // Per frame: milliseconds a detection, the whole frame alone and with the search.
    let mut times: Vec<[Vec<f64>; 2]> = frames.iter().map(|_| [Vec::new(), Vec::new()]).collect();
    for _ in 0..rounds {
        for ((name, img, has_face), t) in frames.iter().zip(&mut times) {
            let frame = Frame::packed_rgb(&img.data, img.width, img.height);
            let (mut whole, mut searching) = (detector()?, detector()?);
            // Found first, as the tracker following it would have it.
            let mut tries = 0;
            while searching
                .detect(&frame)
                .map_err(|e| e.to_string())?
                .is_empty()
                && *has_face
            {
                tries += 1;
                if tries > FIND_WITHIN {
                    return Err(format!("{name}: no face found in {FIND_WITHIN} detections"));
                }
            }
            for _ in 0..REPEATS {
                let start = Instant::now();
                whole
                    .detect_whole_frame(&frame)
                    .map_err(|e| e.to_string())?;
                t[0].push(start.elapsed().as_secs_f64() * 1e3);
                let start = Instant::now();
                searching.detect(&frame).map_err(|e| e.to_string())?;
                t[1].push(start.elapsed().as_secs_f64() * 1e3);
            }
        }
    }
    let interval = TrackerSettings::default().detect_interval as f64;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "Made by `cargo run --release --example benchmark -- --face-search --rounds {rounds}`: \
         1920 x 1080 RGB, one thread, {REPEATS} detections a frame in each of {rounds} interleaved rounds; \
         median (min-max) ms, each face found first. A frame's share is the mean detection's over the tracker's \
         interval of {interval} frames: following a lone small face, two detections in three look only where \
         it was boxed, and cost less.\n"
    );
    let _ = writeln!(
        md,
        "| frame | whole frame alone, ms a detection | with the search | ratio | with the search, mean ms a frame |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|");
    for ((name, ..), [alone, search]) in frames.iter().zip(times) {
        let (a, a_lo, a_hi) = median_min_max(alone);
        let mean = search.iter().sum::<f64>() / search.len() as f64;
        let (s, s_lo, s_hi) = median_min_max(search);
        let _ = writeln!(
            md,
            "| {name} | {a:.2} ({a_lo:.2}-{a_hi:.2}) | {s:.2} ({s_lo:.2}-{s_hi:.2}) | {:.2}x | {:.2} |",
            s / a,
            mean / interval
        );
    }
    Ok(md)
}
