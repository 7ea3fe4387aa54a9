//! How strong the relighting is over a face and which way its light falls,
//! per preset: on a real portrait in 720p and a real film clip (no ground
//! truth; with the box-edge and mottling measures beside them, so a weaker
//! effect cannot pass for a cleaner one), and on the simulator's `call`,
//! where the exact render under each light gives what the truth's change is.
//! Writes `<out>/direction.md`, before/after sheets `<out>/<clip>.png`
//! (input, warm-key-left, cool-key-right, neon) and the maps of those
//! changes, `<out>/<clip>-change.png` (grey for none, lighter for brighter).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use deskstage::dataset::Stage;
use deskstage::monitor::RgbImage;
use gst::prelude::*;
use gstlsydrelight::frame::OwnedFrame;
use gstlsydrelight::targets::Preset;
use lsydrelight_testkit::{
    checkout,
    direction::{LightShape, light_shape},
    footage::{Format, Relit, decode, denoised, portrait_720p, read_y4m, relight_with, through},
    init,
    quality::{self, Region, View, box_edges, change_map, mottling},
    recording::ensure_clean_face,
};

/// Contrasting presets: a front light, keys from each side, a rim, and two colours.
const PRESETS: [Preset; 6] = [
    Preset::SoftFront,
    Preset::WarmKeyLeft,
    Preset::CoolKeyRight,
    Preset::Rim,
    Preset::Sunset,
    Preset::Neon,
];

/// The presets a before/after sheet shows after the input.
const SHOWN: [Preset; 3] = [Preset::WarmKeyLeft, Preset::CoolKeyRight, Preset::Neon];

/// Frames a still is shown for; the first few settle the element's temporal filters.
const STILL_FRAMES: usize = 8;

/// One clip relit to one preset.
struct Relighting {
    /// Per frame relit at full strength: its index, the face the element
    /// marked in it, and the shape of the change over that face.
    faces: Vec<(usize, Region)>,
    shapes: Vec<LightShape>,
    /// The largest box edge over the frames, in all and where the picture
    /// has no edge, and the median mottling over the face.
    box_edge: f64,
    unexplained_box_edge: f64,
    face_mottling: f64,
    /// The last frame's output, the map of its change (`change_map`) and the
    /// square the element relit in it, for the sheets.
    last: RgbImage,
    last_change: RgbImage,
    last_square: Option<Region>,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The relit frames with the face regions the element marked (at full strength).
fn relit_at_full_strength<'a>(
    relit: &'a [(OwnedFrame, Option<Relit>)],
) -> impl Iterator<Item = (usize, Relit)> + 'a {
    relit.iter().enumerate().filter_map(|(k, (_, r))| {
        r.filter(|r| r.shown.is_some_and(|(strength, _)| strength >= 0.999))
            .map(|r| (k, r))
    })
}

/// The element as measured: its model, and its `source-preset` where it is not
/// the element's default.
pub struct Setup {
    pub model: PathBuf,
    pub source_preset: Option<Preset>,
}

impl Setup {
    fn properties(&self, target: Preset) -> String {
        let source = (self.source_preset)
            .map(|p| format!(" source-preset={}", p.nick()))
            .unwrap_or_default();
        format!(
            "target-preset={} target-transition=0{source}",
            target.nick()
        )
    }

    /// The source light the element assumes without a monitor stream
    /// (`Preset::None`: it predicts one).
    fn source(&self) -> Result<Preset, String> {
        match self.source_preset {
            Some(p) => Ok(p),
            None => gst::ElementFactory::make("lsydrelight")
                .build()
                .map(|e| e.property::<Preset>("source-preset"))
                .map_err(|e| format!("lsydrelight: {e}")),
        }
    }

    fn describe(&self) -> String {
        let model = self.model.strip_prefix(checkout()).unwrap_or(&self.model);
        match self.source_preset {
            Some(p) => format!("`{}` and `source-preset={}`", model.display(), p.nick()),
            None => format!("`{}`", model.display()),
        }
    }
}

/// `frames` relit by the `setup`'s element to `preset` and measured against the input as
/// the element's denoising left it (so that the change measured is the light's).
fn relight(frames: &[RgbImage], setup: &Setup, preset: Preset) -> Result<Relighting, String> {
    let relit = relight_with(frames, &setup.model, &setup.properties(preset), Format::Rgb)?;
    let regions: Vec<Option<Relit>> = relit.iter().map(|(_, r)| *r).collect();
    let input = denoised(&through(frames, Format::Rgb)?, &regions)?;
    let (mut faces, mut shapes, mut mottles) = (Vec::new(), Vec::new(), Vec::new());
    let (mut edges, mut unexplained) = (Vec::new(), Vec::new());
    for (k, r) in relit_at_full_strength(&relit) {
        let (i, o) = (input[k].frame(), relit[k].0.frame());
        let face = r.face;
        faces.push((k, face));
        shapes.push(light_shape(&View::pixels(i), &View::pixels(o), face));
        let (luma_in, luma_out) = (View::brightness(i), View::brightness(o));
        let both = box_edges(&luma_in, &luma_out);
        edges.push(both.all.score);
        unexplained.push(both.unexplained.score);
        mottles.push(mottling(&View::colour(i), &View::colour(o), face));
    }
    if shapes.is_empty() {
        return Err(format!(
            "{}: no frame was relit at full strength (no face found?)",
            preset.nick()
        ));
    }
    let (last_frame, last_relit) = relit.last().expect("frames");
    let last = View::pixels(last_frame.frame()).to_rgb_image();
    let last_input = input.last().expect("frames").frame();
    let last_change = change_map(
        &View::brightness(last_input),
        &View::brightness(last_frame.frame()),
    );
    let last_square = last_relit.map(|r| r.region);
    Ok(Relighting {
        faces,
        shapes,
        box_edge: edges.into_iter().fold(0.0, f64::max),
        unexplained_box_edge: unexplained.into_iter().fold(0.0, f64::max),
        face_mottling: median(mottles),
        last,
        last_change,
        last_square,
    })
}

/// Median over frames of the difference of two relightings' asymmetries.
fn key_swap(left: &[LightShape], right: &[LightShape]) -> f64 {
    median(
        left.iter()
            .zip(right)
            .map(|(l, r)| l.asymmetry - r.asymmetry)
            .collect(),
    )
}

fn median_strength(shapes: &[LightShape]) -> f64 {
    median(shapes.iter().map(|s| s.strength).collect())
}

/// A row of images, each cut to `square` (the square the element relit)
/// where there is one and scaled to `height` rows, with a gap between them.
fn sheet(images: &[&RgbImage], square: Option<Region>, height: u32) -> image::RgbImage {
    let gap = 6;
    let scaled: Vec<image::RgbImage> = images
        .iter()
        .map(|img| {
            let raw =
                image::RgbImage::from_raw(img.width as u32, img.height as u32, img.data.clone())
                    .expect("an RGB image");
            let shown = match square {
                Some(r) => {
                    let size = r.size.min(img.width - r.x).min(img.height - r.y) as u32;
                    image::imageops::crop_imm(&raw, r.x as u32, r.y as u32, size, size).to_image()
                }
                None => raw,
            };
            let width = (shown.width() * height).div_ceil(shown.height());
            image::imageops::resize(&shown, width, height, image::imageops::FilterType::Triangle)
        })
        .collect();
    let width = scaled.iter().map(|s| s.width() + gap).sum::<u32>() - gap;
    let mut out = image::RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
    let mut x = 0;
    for s in &scaled {
        image::imageops::overlay(&mut out, s, x as i64, 0);
        x += s.width() + gap;
    }
    out
}

/// The report: real footage, then the simulator against its truth.
pub fn report(frames: usize, setup: &Setup, out: &Path, stage: Stage) -> Result<(), String> {
    init();
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let media = checkout().join("target/real-media");
    let portrait = portrait_720p(&media)?;
    let clips: [(&str, Vec<RgbImage>); 2] = [
        ("astronaut-720p", vec![portrait; STILL_FRAMES]),
        ("megamind", decode(&media.join("Megamind.avi"), frames)?),
    ];
    let mut md = String::new();
    let _ = writeln!(
        md,
        "Made by `cargo run --release --example target_lights -- direction --frames {frames} --stage {}` \
         with {} and the element's other defaults, fed RGB, with no monitor stream.\n\n\
         Strength: RMS over the face of 100 ln((out + 10) / (in + 10)), luma in levels, in %. \
         Key swap: the face's image-left less image-right mean change under warm-key-left, \
         less the same under cool-key-right, in %. Box edge: the largest \
         straight step in the change where the picture itself has none, and in all \
         (`lsydrelight_testkit::quality`), largest over the frames and presets; face mottling as \
         `examples/real_footage.rs` measures it (median).\n",
        stage.name(),
        setup.describe()
    );
    let _ = writeln!(md, "## Real footage\n");
    let header: Vec<&str> = PRESETS.iter().map(|p| p.nick()).collect();
    let _ = writeln!(
        md,
        "| clip | strength: {} | median strength | key swap | box edge where the picture has none (in all) | face mottling |",
        header.join(" / ")
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|");
    // A target that is the source light the element assumes passes unchanged.
    let source = setup.source()?;
    for (name, frames) in &clips {
        let relit: Vec<(Preset, Relighting)> = PRESETS
            .iter()
            .filter(|&&p| p != source)
            .map(|&p| {
                eprintln!("{name}: {}", p.nick());
                relight(frames, setup, p).map(|r| (p, r))
            })
            .collect::<Result<_, _>>()?;
        let of = |preset: Preset| {
            relit
                .iter()
                .find_map(|(p, r)| (*p == preset).then_some(r))
                .ok_or_else(|| {
                    format!(
                        "{} is the source light, so it is not measured",
                        preset.nick()
                    )
                })
        };
        let strengths: Vec<f64> = PRESETS
            .iter()
            .map(|&p| of(p).map_or(0.0, |r| median_strength(&r.shapes)))
            .collect();
        let per_preset: Vec<String> = strengths.iter().map(|s| format!("{s:.1}")).collect();
        let (rs, square) = (relit.iter().map(|(_, r)| r), relit[0].1.last_square);
        let _ = writeln!(
            md,
            "| {name} | {} | {:.1} | {:+.1} | {:.1} ({:.1}) | {:.2} |",
            per_preset.join(" / "),
            median(strengths.clone()),
            key_swap(
                &of(Preset::WarmKeyLeft)?.shapes,
                &of(Preset::CoolKeyRight)?.shapes
            ),
            rs.clone()
                .map(|r| r.unexplained_box_edge)
                .fold(0.0, f64::max),
            rs.clone().map(|r| r.box_edge).fold(0.0, f64::max),
            median(rs.map(|r| r.face_mottling).collect()),
        );
        let mut shown = vec![frames.last().expect("frames")];
        let mut changes = Vec::new();
        for preset in SHOWN {
            shown.push(&of(preset)?.last);
            changes.push(&of(preset)?.last_change);
        }
        let path = out.join(format!("{name}.png"));
        sheet(&shown, square, 360)
            .save(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        let path = out.join(format!("{name}-change.png"));
        sheet(&changes, square, 360)
            .save(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
    }
    if source != Preset::None {
        let _ = writeln!(
            md,
            "\n{} is the source light the element assumes (`source-preset`): it passes unchanged, \
             strength 0.",
            source.nick()
        );
    }
    simulator(frames, setup, out, stage, &mut md)?;
    let path = out.join("direction.md");
    std::fs::write(&path, &md).map_err(|e| format!("{}: {e}", path.display()))?;
    print!("{md}");
    Ok(())
}

/// The simulator's `call`: the truth's change (its exact render under each
/// preset over the noiseless face) beside the element's, over the face the
/// element marked.
fn simulator(
    frames: usize,
    setup: &Setup,
    out: &Path,
    stage: Stage,
    md: &mut String,
) -> Result<(), String> {
    // The call was lit by its screen, which the truth is relit from: without the
    // monitor stream here, the element predicts that light rather than assume one.
    let setup = &Setup {
        model: setup.model.clone(),
        source_preset: Some(Preset::None),
    };
    let (dir, _) = super::call_recording(frames, stage)?;
    let clean_path = dir.join("clean-face.y4m");
    ensure_clean_face(&clean_path, "call", frames)?;
    let clean = read_y4m(&clean_path, frames)?;
    let face = read_y4m(&dir.join("face.y4m"), frames)?;
    let _ = writeln!(
        md,
        "\n## Simulator (`call`, {frames} frames, the targets' truth lit from the {}): the exact truth beside the element, its source light predicted (`source-preset=none`)\n",
        stage.name()
    );
    let _ = writeln!(
        md,
        "| preset | truth's strength | element's strength | truth's asymmetry | element's asymmetry | truth's box edge, unexplained (in all) | element's |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|---|---|");
    let mut swaps = ([0.0; 2], [0.0; 2]);
    let mut sheet_images = vec![face.last().expect("frames").clone()];
    let mut square = None;
    for preset in PRESETS {
        let relit = relight(&face, setup, preset)?;
        let truth = read_y4m(
            &dir.join(format!("truth-preset-{}.y4m", preset.nick())),
            frames,
        )?;
        let truth_shapes: Vec<LightShape> = (relit.faces.iter())
            .map(|&(k, face)| light_shape(&clean[k], &truth[k], face))
            .collect();
        // The box edge of the truth's own change: what a relighting as strong
        // as the truth's scores on that measure (clipped highlights, a lit
        // face against a dark room).
        let truth_both: Vec<_> = (relit.faces.iter())
            .map(|&(k, _)| box_edges(&clean[k], &truth[k]))
            .collect();
        let largest = |score: fn(&_) -> f64| truth_both.iter().map(score).fold(0.0, f64::max);
        let truth_edge = largest(|e: &quality::BoxEdges| e.all.score);
        let truth_unexplained = largest(|e: &quality::BoxEdges| e.unexplained.score);
        let asymmetry = |s: &[LightShape]| median(s.iter().map(|s| s.asymmetry).collect());
        let (truth_asym, element_asym) = (asymmetry(&truth_shapes), asymmetry(&relit.shapes));
        let _ = writeln!(
            md,
            "| {} | {:.1} | {:.1} | {truth_asym:+.1} | {element_asym:+.1} | {truth_unexplained:.1} ({truth_edge:.1}) | {:.1} ({:.1}) |",
            preset.nick(),
            median_strength(&truth_shapes),
            median_strength(&relit.shapes),
            relit.unexplained_box_edge,
            relit.box_edge,
        );
        match preset {
            Preset::WarmKeyLeft => swaps = ([truth_asym, element_asym], swaps.1),
            Preset::CoolKeyRight => swaps = (swaps.0, [truth_asym, element_asym]),
            _ => {}
        }
        if SHOWN[..2].contains(&preset) {
            sheet_images.push(truth.last().expect("frames").clone());
            square = relit.last_square;
            sheet_images.push(relit.last);
        }
    }
    let _ = writeln!(
        md,
        "\nKey swap (warm-key-left's asymmetry less cool-key-right's): truth {:+.1}, element {:+.1}.",
        swaps.0[0] - swaps.1[0],
        swaps.0[1] - swaps.1[1]
    );
    let path = out.join("call.png");
    let images: Vec<&RgbImage> = sheet_images.iter().collect();
    sheet(&images, square, 240)
        .save(&path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let _ = writeln!(
        md,
        "\n`call.png`: input, then warm-key-left's truth and output, cool-key-right's truth and output."
    );
    Ok(())
}
