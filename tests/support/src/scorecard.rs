//! The measures of [`crate::quality`] on real footage and on the simulator's
//! recordings, through the element with no monitor stream: the report that
//! `examples/real_footage.rs` prints and `examples/benchmark.rs --quality`
//! writes into the benchmark's results.
//!
//! The real clips come from packages, fetched by `scripts/setup.sh full` into
//! `target/real-media` (never committed): scikit-image's `astronaut.png` (PyPI,
//! public domain), shown as a still video, and Debian opencv-doc's
//! `Megamind.avi` (a film clip, for robustness only). The recordings are the
//! simulator's `wander` (a person walking about the frame and out of it) and
//! the benchmark's `steady`, `slow`, `cuts` and `call`, each relit to its own
//! sunset target and scored against its exact ground truth as well.
//!
//! The measures read the lighting change as output over input, pixel by
//! pixel, so with the denoising on they compare the output with the input as
//! the element's denoising left it, filtered again by the element's own code
//! ([`crate::footage::denoised`]); the notes below the tables give what the
//! denoising alone changed. Fed I420, the element's I420 output is compared
//! with the I420 it was fed, read as the format carries light and colour
//! ([`View`]); the notes also give the element fed RGB with its output and its
//! input both converted to I420: what the format itself does to the measures.

use std::path::Path;

use deskstage::monitor::RgbImage;
use gstlsydrelight::frame::{Frame, OwnedFrame};

use crate::checkout;
use crate::footage::{Format, Relit, decode, denoised, read_y4m, relight, through};
use crate::quality::{
    BoxEdge, BoxEdges, Pixels, Region, SquareMeans, View, box_edge_score, box_edges, change_map,
    mean_level, mottling, mottling_by_luma, mottling_in_all, pumping,
};
use crate::recording::ensure_recording;

/// One clip's measures.
pub struct Measured {
    pub name: String,
    pub frames: usize,
    pub box_edge_max: f64,
    pub box_edge_median: f64,
    /// The largest box edge where the picture has none ([`box_edges`]):
    /// the bar `tests/real_footage.rs` holds.
    pub unexplained_box_edge_max: f64,
    pub mottling_median: f64,
    /// The same over the face alone (the face within the relit square, [`Relit::face`]),
    /// as issue 12 defines the measure; the square holds hair and room too.
    pub face_mottling_median: f64,
    /// The same counting the face's near-black pixels too ([`mottling_in_all`]).
    pub face_mottling_in_all_median: f64,
    pub pumping: f64,
    /// Where the largest box edge is, in all and where the picture has none.
    pub worst: String,
    /// Where the mottling comes from, by band of input luma ([`LUMA_BANDS`]).
    pub mottling_sources: String,
    /// Fed another format than RGB: the element fed RGB instead, its output
    /// and its input both then round the trip through the format, scored the
    /// same way: the largest box edge and the median mottling.
    pub through_format: Option<(f64, f64, f64)>,
    /// With the denoising on, what it changed alone (the input against the
    /// input denoised), by the same measures: the largest box edge and the
    /// median mottling over the face.
    pub denoising: Option<(f64, f64)>,
    /// Against the ground truth, where there is one: RMSE (0-255) of the output
    /// over the relit square and over the whole frame, and the same for the input.
    pub truth: Option<[f64; 4]>,
}

impl Measured {
    /// The columns every table has, as a markdown row left open at the end.
    pub fn row(&self) -> String {
        format!(
            "| {} | {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} ({:.2}) | {:.2}",
            self.name,
            self.frames,
            self.unexplained_box_edge_max,
            self.box_edge_max,
            self.box_edge_median,
            self.mottling_median,
            self.face_mottling_median,
            self.face_mottling_in_all_median,
            self.pumping
        )
    }
}

/// RMSE (0-255) of `a` against `b` over `region`, or over the whole frame.
fn rmse(a: &impl Pixels, b: &impl Pixels, region: Option<Region>) -> f64 {
    let (w, h) = a.size();
    let r = region.unwrap_or(Region {
        x: 0,
        y: 0,
        size: w.max(h),
    });
    let (mut sum, mut count) = (0.0, 0usize);
    for y in r.y..(r.y + r.size).min(h) {
        for x in r.x..(r.x + r.size).min(w) {
            let (p, q) = (a.rgb(x, y), b.rgb(x, y));
            sum += (0..3).map(|c| (255.0 * (p[c] - q[c])).powi(2)).sum::<f64>();
            count += 3;
        }
    }
    (sum / count.max(1) as f64).sqrt()
}

/// Each frame read one way ([`View::pixels`], [`View::brightness`] or [`View::colour`]).
fn read<'a>(frames: &'a [OwnedFrame], reading: fn(Frame<'a>) -> View<'a>) -> Vec<View<'a>> {
    frames.iter().map(|f| reading(f.frame())).collect()
}

/// Edges, in levels of input luma, of the bands the mottling is broken down by.
const LUMA_BANDS: [f64; 3] = [8.0, 16.0, 64.0];

/// One frame's mottling over every pixel of the face, and per band of input
/// luma its share of the face and of the mottling's sum of squares.
type MottlingByLuma = (f64, Vec<(f64, f64)>);

/// Per band of input luma (median over the frames): its share of the face
/// (the measure: the face within the relit square, `faces`), its share
/// of the mottling's sum of squares and the mottling over its pixels alone;
/// and the median mottling over every pixel of the face ([`mottling_in_all`]).
fn mottling_sources(input: &[View], output: &[View], faces: &[Region]) -> (String, f64) {
    let frames: Vec<MottlingByLuma> = input
        .iter()
        .zip(output)
        .zip(faces)
        .map(|((i, o), &face)| {
            (
                mottling_in_all(i, o, face),
                mottling_by_luma(i, o, face, &LUMA_BANDS),
            )
        })
        .collect();
    let of = |f: &dyn Fn(&MottlingByLuma) -> f64| median(frames.iter().map(f).collect());
    let names = ["under 8", "8-16", "16-64", "64 up"];
    let bands: Vec<String> = names
        .iter()
        .enumerate()
        .map(|(b, name)| {
            let rms = of(&|(m, bands)| {
                let (pixels, sum) = bands[b];
                if pixels > 0.0 {
                    m * (sum / pixels).sqrt()
                } else {
                    0.0
                }
            });
            format!(
                "{name}: {:.0}% of the face, {:.0}% of the sum, {rms:.2}%",
                100.0 * of(&|(_, bands)| bands[b].0),
                100.0 * of(&|(_, bands)| bands[b].1),
            )
        })
        .collect();
    (bands.join("; "), of(&|(m, _)| *m))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Where to measure a frame the element did not mark: the centred square of full height.
fn centred_square(frame: &OwnedFrame) -> Region {
    let size = frame.width.min(frame.height);
    Region {
        x: (frame.width - size) / 2,
        y: (frame.height - size) / 2,
        size,
    }
}

/// Input and output side by side.
fn before_after(before: &RgbImage, after: &RgbImage) -> RgbImage {
    let gap = 8;
    let (w, h) = (before.width, before.height);
    let total = 2 * w + gap;
    let mut data = vec![255u8; total * h * 3];
    for (x0, img) in [(0, before), (w + gap, after)] {
        for y in 0..h {
            let row = &img.data[y * w * 3..(y + 1) * w * 3];
            data[(y * total + x0) * 3..(y * total + x0 + w) * 3].copy_from_slice(row);
        }
    }
    RgbImage {
        width: total,
        height: h,
        data,
    }
}

/// How the element is run on every clip: the model, the target, the format
/// it is fed and whether it denoises.
#[derive(Clone, Copy)]
pub struct Setup<'a> {
    pub model: &'a Path,
    pub target: &'a Path,
    pub format: Format,
    pub denoise: bool,
}

impl Setup<'_> {
    fn relight(
        &self,
        input: &[RgbImage],
        format: Format,
    ) -> Result<Vec<(OwnedFrame, Option<Relit>)>, String> {
        relight(input, self.model, self.target, format, self.denoise)
    }
}

/// One clip through the element as `setup` says, measured, with its
/// before/after image and map of the change written into `images`.
pub fn measure(
    name: &str,
    input: Vec<RgbImage>,
    truth: Option<Vec<RgbImage>>,
    setup: &Setup,
    images: &Path,
) -> Result<Measured, String> {
    let format = setup.format;
    // The element is fed the frames converted once, and its output is
    // compared with those frames, byte for byte what it was fed.
    let (output, relits): (Vec<OwnedFrame>, Vec<Option<Relit>>) =
        setup.relight(&input, format)?.into_iter().unzip();
    let through_format = if format == Format::Rgb {
        None
    } else {
        let (relit, relits): (Vec<OwnedFrame>, Vec<_>) =
            setup.relight(&input, Format::Rgb)?.into_iter().unzip();
        let mut changed = through(&input, Format::Rgb)?;
        if setup.denoise {
            changed = denoised(&changed, &relits)?;
        }
        let rgb = |frames: &[OwnedFrame]| -> Vec<RgbImage> {
            read(frames, View::pixels)
                .iter()
                .map(View::to_rgb_image)
                .collect()
        };
        Some((
            through(&rgb(&changed), format)?,
            through(&rgb(&relit), format)?,
        ))
    };
    let input = through(&input, format)?;
    // The measures look at the square the element relit (its part inside
    // the frame) and the face within it.
    let (regions, faces): (Vec<Region>, Vec<Region>) = relits
        .iter()
        .zip(&input)
        .map(|(r, frame)| {
            r.map_or_else(
                || {
                    let square = centred_square(frame);
                    (square, square.face_within())
                },
                |r| (r.region, r.face),
            )
        })
        .unzip();
    // What the lighting change was applied to: the input, or the input as
    // the denoising left it.
    let changed = if setup.denoise {
        denoised(&input, &relits)?
    } else {
        input.clone()
    };
    let denoising = setup.denoise.then(|| {
        let edge = read(&input, View::brightness)
            .iter()
            .zip(&read(&changed, View::brightness))
            .map(|(i, d)| box_edge_score(i, d))
            .fold(0.0, f64::max);
        let face_mottled = mottlings(
            &read(&input, View::colour),
            &read(&changed, View::colour),
            &regions,
            &faces,
        )
        .1;
        (edge, median(face_mottled))
    });
    let both: Vec<BoxEdges> = read(&changed, View::brightness)
        .iter()
        .zip(&read(&output, View::brightness))
        .map(|(i, o)| box_edges(i, o))
        .collect();
    let worst = |edge: fn(&BoxEdges) -> BoxEdge| {
        let (frame, worst) = (both.iter().map(edge))
            .enumerate()
            .max_by(|a, b| a.1.score.total_cmp(&b.1.score))
            .expect("at least one frame");
        format!(
            "frame {frame}: {:.1}% across {} = {}, {} from {}",
            worst.score,
            if worst.vertical { "x" } else { "y" },
            worst.across,
            if worst.vertical { "y" } else { "x" },
            worst.along
        )
    };
    let worst = format!(
        "{}; where the picture has none, {}",
        worst(|e| e.all),
        worst(|e| e.unexplained)
    );
    let edges: Vec<f64> = both.iter().map(|e| e.all.score).collect();
    let unexplained_box_edge_max = (both.iter())
        .map(|e| e.unexplained.score)
        .fold(0.0, f64::max);
    let (changed_colour, output_colour) =
        (read(&changed, View::colour), read(&output, View::colour));
    let (mottled, face_mottled) = mottlings(&changed_colour, &output_colour, &regions, &faces);
    let through_format = through_format.map(|(i, o)| {
        let edge = read(&i, View::brightness)
            .iter()
            .zip(&read(&o, View::brightness))
            .map(|(i, o)| box_edge_score(i, o))
            .fold(0.0, f64::max);
        let (mottled, face_mottled) = mottlings(
            &read(&i, View::colour),
            &read(&o, View::colour),
            &regions,
            &faces,
        );
        (edge, median(mottled), median(face_mottled))
    });
    let input_colour = read(&input, View::colour);
    let means: Vec<SquareMeans> = input_colour
        .iter()
        .zip(&output_colour)
        .zip(regions.iter().zip(&relits))
        .map(|((i, o), (&r, relit))| SquareMeans {
            input: mean_level(i, r),
            output: mean_level(o, r),
            fading: relit.as_ref().is_some_and(Relit::fading),
        })
        .collect();
    let (input_pixels, output_pixels) = (read(&input, View::pixels), read(&output, View::pixels));
    let truth = truth.map(|truth| {
        let mean =
            |f: &dyn Fn(usize) -> f64| (0..input.len()).map(f).sum::<f64>() / input.len() as f64;
        [
            mean(&|k| rmse(&output_pixels[k], &truth[k], Some(regions[k]))),
            mean(&|k| rmse(&output_pixels[k], &truth[k], None)),
            mean(&|k| rmse(&input_pixels[k], &truth[k], Some(regions[k]))),
            mean(&|k| rmse(&input_pixels[k], &truth[k], None)),
        ]
    });
    let shown = input.len() / 2;
    let image = images.join(format!("{name}-before-after.png"));
    let (before, after) = (
        input_pixels[shown].to_rgb_image(),
        output_pixels[shown].to_rgb_image(),
    );
    deskstage::io::write_png(&image, &before_after(&before, &after))
        .map_err(|e| format!("{}: {e}", image.display()))?;
    let image = images.join(format!("{name}-change.png"));
    let map = change_map(
        &View::brightness(changed[shown].frame()),
        &View::brightness(output[shown].frame()),
    );
    deskstage::io::write_png(&image, &map).map_err(|e| format!("{}: {e}", image.display()))?;
    let (mottling_sources, face_mottling_in_all_median) =
        mottling_sources(&changed_colour, &output_colour, &faces);
    Ok(Measured {
        mottling_sources,
        through_format,
        denoising,
        worst,
        truth,
        name: name.to_string(),
        frames: input.len(),
        box_edge_max: edges.iter().copied().fold(0.0, f64::max),
        unexplained_box_edge_max,
        box_edge_median: median(edges),
        mottling_median: median(mottled),
        face_mottling_median: median(face_mottled),
        face_mottling_in_all_median,
        pumping: pumping(&means),
    })
}

/// Per frame, the mottling of `output` against `input` over the relit square
/// (`regions`) and over the face within it (`faces`).
fn mottlings(
    input: &[View],
    output: &[View],
    regions: &[Region],
    faces: &[Region],
) -> (Vec<f64>, Vec<f64>) {
    input
        .iter()
        .zip(output)
        .zip(regions.iter().zip(faces))
        .map(|((i, o), (&r, &face))| (mottling(i, o, r), mottling(i, o, face)))
        .unzip()
}

/// What the report says about a clip below its tables: where its mottling
/// comes from, what the denoising alone changed and, fed another format,
/// the RGB path's output through it.
fn notes_of(m: &Measured, format: Format) -> Vec<String> {
    let mut notes = vec![format!(
        "{}: mottling over every pixel of the face by input luma (levels), median over the frames: {}",
        m.name, m.mottling_sources
    )];
    if let Some((edge, face_mottled)) = m.denoising {
        notes.push(format!(
            "{}: the denoising alone (the input against the input denoised): \
             box edge max {edge:.1}%, mottling over the face {face_mottled:.2}%",
            m.name
        ));
    }
    if let Some((edge, mottled, face_mottled)) = m.through_format {
        notes.push(format!(
            "{}: the element fed RGB, its output and input both through {format:?}: \
             box edge max {edge:.1}%, mottling median {mottled:.2}%, over the face {face_mottled:.2}%",
            m.name
        ));
    }
    notes
}

/// The real clips: (name, file in the media folder).
const CLIPS: [(&str, &str); 2] = [("astronaut", "astronaut.png"), ("megamind", "Megamind.avi")];

/// The simulator's recordings: (name, length in frames).
const RECORDINGS: [(&str, usize); 5] = [
    ("steady", 300),
    ("wander", 45),
    ("slow", 300),
    ("cuts", 300),
    ("call", 90),
];

/// The report, in markdown: the real clips in `media` (the first `frames`
/// frames) relit as `setup` says, then the simulator's recordings relit to
/// their own targets and scored against their truth too, then notes on
/// each. Before/after images and maps of the change go into `images`. With
/// names in `only`, just the clips and recordings so named.
pub fn report(
    setup: &Setup,
    media: &Path,
    frames: usize,
    images: &Path,
    only: &[String],
) -> Result<String, String> {
    let known = || {
        CLIPS
            .map(|c| c.0)
            .into_iter()
            .chain(RECORDINGS.map(|r| r.0))
    };
    if let Some(unknown) = only.iter().find(|o| !known().any(|k| k == o.as_str())) {
        return Err(format!(
            "no clip or recording is called {unknown}: name one of {}",
            known().collect::<Vec<_>>().join(", ")
        ));
    }
    let wanted = |name: &str| only.is_empty() || only.iter().any(|o| o == name);
    std::fs::create_dir_all(images).map_err(|e| format!("{}: {e}", images.display()))?;
    let format = setup.format;
    let mut lines = vec![
        format!(
            "The element fed {format:?}, denoising {}.",
            if setup.denoise {
                "on: the measures compare the output with the input as the denoising left it"
            } else {
                "off"
            }
        ),
        String::new(),
        "| clip | frames | box edge where the picture has none, max % | box edge max % | box edge median % | mottling median % | over the face % (in all) | pumping (levels) |".into(),
        "|---|---|---|---|---|---|---|---|".into(),
    ];
    let (mut worst, mut notes) = (Vec::new(), Vec::new());
    for (name, file) in CLIPS.into_iter().filter(|(name, _)| wanted(name)) {
        let path = media.join(file);
        if !path.exists() {
            return Err(format!(
                "{} is missing: run scripts/setup.sh full, which fetches it",
                path.display()
            ));
        }
        let m = measure(name, decode(&path, frames)?, None, setup, images)?;
        lines.push(format!("{} |", m.row()));
        worst.push(format!("{}: largest box edge at {}", m.name, m.worst));
        notes.extend(notes_of(&m, format));
    }
    lines.extend([
        String::new(),
        "| recording | frames | box edge where the picture has none, max % | box edge max % | box edge median % | mottling median % | over the face % (in all) | pumping (levels) | RMSE relit square | RMSE frame | input RMSE square | input RMSE frame |".into(),
        "|---|---|---|---|---|---|---|---|---|---|---|---|".into(),
    ]);
    for (recording, length) in RECORDINGS.into_iter().filter(|(name, _)| wanted(name)) {
        let dir = checkout().join(format!("target/recordings/{recording}-{length}"));
        ensure_recording(&dir, recording, length)?;
        let input = read_y4m(&dir.join("face.y4m"), frames)?;
        let truth = read_y4m(&dir.join("truth-sunset.y4m"), frames)?;
        let target = dir.join("target-sunset.png");
        let own_target = Setup {
            target: &target,
            ..*setup
        };
        let m = measure(recording, input, Some(truth), &own_target, images)?;
        let t = m.truth.expect("a recording has its truth");
        lines.push(format!(
            "{} | {:.2} | {:.2} | {:.2} | {:.2} |",
            m.row(),
            t[0],
            t[1],
            t[2],
            t[3]
        ));
        worst.push(format!("{}: largest box edge at {}", m.name, m.worst));
        notes.extend(notes_of(&m, format));
    }
    lines.push(String::new());
    lines.extend(worst.into_iter().chain(notes).map(|l| format!("- {l}")));
    Ok(lines.join("\n") + "\n")
}
