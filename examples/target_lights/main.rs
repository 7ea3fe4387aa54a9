//! Every kind of target light, shown and measured: the README's contact sheet
//! of the presets, its picture of how an environment map becomes a monitor
//! light, the error of relighting to each against the simulator's exact ground
//! truth, and what target changes and video targets cost.
//!
//! ```text
//! cargo run --example target_lights -- sheet results/targets/presets.png
//! cargo run --example target_lights -- projection results/targets/environment.png
//! cargo run --example target_lights -- measure [--frames 60] [--model models/default] [--paste-alone] [--set PROPERTY=VALUE]...
//! cargo run --example target_lights -- timing
//! cargo run --release --example target_lights -- direction [--frames 30] [--model models/starter] \
//!     [--out results/direction]
//! ```
//!
//! `direction` measures how strong the relighting is over the face and which
//! way its light falls (`lsydrelight_testkit::direction`): on real portraits
//! and clips (from `scripts/setup.sh full`) and on the simulator's `call`,
//! where the exact render under each light says what the truth gives.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::{Parser, Subcommand};
use deskstage::content::{FRAME_HEIGHT, FRAME_WIDTH};
use deskstage::dataset::{Recording, RecordingSpec, Stage, light_of};
use deskstage::math::Vec3;
use deskstage::monitor::RgbImage;
use deskstage::subject::State;
use gst::prelude::*;
use gst_check::Harness;
use gstlsydrelight::engine::contract::Manifest;
use gstlsydrelight::light::{LIGHT_COLS, LIGHT_ROWS, Light, linear_to_srgb_byte};
use gstlsydrelight::targets::{Panorama, Preset, View};
use lsydrelight_testkit::{
    checkout, default_model,
    element::{element, stat},
    footage::{
        Format, PORTRAIT_FACE, Relit, decode, denoised, packed, read_y4m, relight_with, unpacked,
    },
    init,
    oracle::truth_pasted,
    person::render_person,
    recording::{face_region_rmse, score_recording},
    video::{FRAME, buffer, frame_time, rgb_caps, to_rgb},
};

/// Every kind of target light, shown and measured.
#[derive(Parser)]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The contact sheet of the presets, as a PNG.
    Sheet { out: PathBuf },
    /// How an environment map becomes a monitor light, as a PNG.
    Projection { out: PathBuf },
    /// The error of relighting to each target against the simulator's exact ground truth.
    Measure {
        /// Frames of the `call` recording.
        #[arg(long, default_value_t = 60)]
        frames: usize,
        /// The model folder (default: models/default, the shipped call's person's
        /// own model; the element's own default is models/starter).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Where the truth's target lights shine from: `desk` (the screen) or
        /// `dome` (the 180-degree field the light code stands for).
        #[arg(long, default_value = "desk", value_parser = Stage::from_name)]
        stage: Stage,
        /// Also the error of the paste alone: each frame's change taken from the
        /// truth's own crop in place of the network's output
        /// (`lsydrelight_testkit::oracle`), pasted where the element relit.
        #[arg(long)]
        paste_alone: bool,
        /// An element property to set on every run, as gst-launch writes it
        /// (`--set alpha=1 --set spread-colour=false`): what a setting costs or
        /// buys against the truth.
        #[arg(long = "set", value_name = "PROPERTY=VALUE", value_parser = property_setting)]
        settings: Vec<(String, String)>,
    },
    /// What target changes and video targets cost.
    Timing,
    /// Strength and direction of the relighting on real faces and the simulator's.
    Direction {
        /// Frames of the `call` recording and of the film clip.
        #[arg(long, default_value_t = 30)]
        frames: usize,
        /// The model folder (default: the element's default, the starter model).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Where the table and the before/after images go.
        #[arg(long, default_value = "results/direction")]
        out: PathBuf,
        /// Where the simulator truth's target lights shine from (as for `measure`).
        #[arg(long, default_value = "desk", value_parser = Stage::from_name)]
        stage: Stage,
        /// The element's `source-preset` (default: the element's default);
        /// `none` predicts the source light from the face.
        #[arg(long, value_parser = preset_named)]
        source_preset: Option<Preset>,
    },
}

/// `PROPERTY=VALUE`, split at its first `=`.
fn property_setting(setting: &str) -> Result<(String, String), String> {
    setting
        .split_once('=')
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .ok_or_else(|| format!("{setting}: write a property setting as PROPERTY=VALUE"))
}

/// A preset by its nick, `none` included.
fn preset_named(nick: &str) -> Result<Preset, String> {
    if nick == Preset::None.nick() {
        return Ok(Preset::None);
    }
    Preset::from_nick(nick).ok_or_else(|| format!("no preset is called {nick}"))
}

mod direction;

fn main() -> Result<(), String> {
    match Args::parse().command {
        Command::Sheet { out } => sheet(&out),
        Command::Projection { out } => projection(&out),
        Command::Measure {
            frames,
            model,
            stage,
            paste_alone,
            settings,
        } => measure(
            frames,
            &model.unwrap_or_else(default_model),
            stage,
            paste_alone,
            &settings,
        ),
        Command::Timing => timing(),
        Command::Direction {
            frames,
            model,
            out,
            stage,
            source_preset,
        } => direction::report(
            frames,
            &direction::Setup {
                model: model.unwrap_or_else(gstlsydrelight::paths::default_model),
                source_preset,
            },
            &checkout().join(out),
            stage,
        ),
    }
}

/// A synthetic outdoor panorama in linear light, 2:1: a blue sky brighter at the
/// horizon, a sun 60 degrees to the right and 25 up, green ground, a red wall to
/// the left and a white window behind.
fn outdoor_panorama(width: usize) -> Panorama {
    let height = width / 2;
    let mut rgb = Vec::with_capacity(width * height);
    for y in 0..height {
        let lat = 90.0 - (y as f64 + 0.5) / height as f64 * 180.0;
        for x in 0..width {
            let lon = (x as f64 + 0.5) / width as f64 * 360.0 - 180.0;
            let sun = ((lon - 60.0).powi(2) + (lat - 25.0).powi(2)).sqrt() < 4.0;
            let wall = (-120.0..-60.0).contains(&lon) && (-20.0..30.0).contains(&lat);
            let window = (lon.abs() > 160.0) && (0.0..40.0).contains(&lat);
            let p: [f32; 3] = if sun {
                [40.0, 32.0, 20.0]
            } else if wall {
                [0.7, 0.12, 0.08]
            } else if window {
                [1.5, 1.5, 1.5]
            } else if lat > 0.0 {
                let t = (lat / 90.0) as f32;
                [0.35 - 0.25 * t, 0.5 - 0.25 * t, 0.8 - 0.2 * t]
            } else {
                [0.08, 0.2, 0.05]
            };
            rgb.push(p);
        }
    }
    Panorama::from_linear(width, height, rgb).expect("a valid panorama")
}

/// Writes the panorama as OpenEXR (for the element, which reads files).
fn write_exr(pano_width: usize, path: &Path) -> Result<(), String> {
    let pano = outdoor_panorama(pano_width);
    let h = pano_width / 2;
    let img = image::Rgb32FImage::from_fn(pano_width as u32, h as u32, |x, y| {
        image::Rgb(pano.pixel(x as usize, y as usize))
    });
    std::fs::create_dir_all(path.parent().unwrap()).map_err(|e| e.to_string())?;
    img.save_with_format(path, image::ImageFormat::OpenExr)
        .map_err(|e| e.to_string())
}

/// A light shown as a monitor frame of `w` x `h`: each cell a flat block.
fn light_frame(light: &Light, w: usize, h: usize) -> RgbImage {
    let n = LIGHT_ROWS * LIGHT_COLS;
    let mut img = RgbImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let cell = (y * LIGHT_ROWS / h) * LIGHT_COLS + x * LIGHT_COLS / w;
            for c in 0..3 {
                img.data[3 * (y * w + x) + c] = linear_to_srgb_byte(light.0[c * n + cell]);
            }
        }
    }
    img
}

/// The face relit to the target the `setup` sets, after a few frames of the same
/// picture (so the temporal filters have settled).
fn relight_still(img: &RgbImage, setup: impl FnOnce(&gst::Element)) -> RgbImage {
    let e = element();
    e.set_property("target-transition", 0u64);
    setup(&e);
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let c = rgb_caps(img.width as u32, img.height as u32, 30);
    h.set_src_caps(c.clone());
    let mut out = None;
    for i in 0..4 {
        h.push(buffer(img, &c, frame_time(i), FRAME)).unwrap();
        out = Some(to_rgb(&h.pull().unwrap(), &c));
    }
    out.unwrap()
}

fn to_image(img: &RgbImage) -> image::RgbImage {
    image::RgbImage::from_raw(img.width as u32, img.height as u32, img.data.clone()).unwrap()
}

/// `img` scaled to `w` x `h` with area averaging.
fn fit(img: &image::RgbImage, w: u32, h: u32) -> image::RgbImage {
    image::imageops::resize(img, w, h, image::imageops::FilterType::Triangle)
}

/// The film clip's frame the contact sheet shows: the face turned to the camera.
const FILM_FRAME: usize = 10;

/// A frame and the square of it the sheet shows (x, y, side); None shows it whole.
struct SheetRow {
    frame: RgbImage,
    shown: Option<(u32, u32, u32)>,
    height: u32,
}

/// The simulator's person, a real portrait and a frame of a real film clip under
/// every preset, each column headed by the preset's monitor picture. Each frame
/// is relit whole, as the element sees it; the portrait's row shows its head and
/// shoulders, three face heights square, so its face is large enough to judge.
fn sheet(out: &Path) -> Result<(), String> {
    init();
    let media = checkout().join("target/real-media");
    let person = render_person(&State::default(), Vec3::new(0.8, 0.8, 0.8), 320, 240);
    let portrait = decode(&media.join("astronaut.png"), 1)?.remove(0);
    let film = decode(&media.join("Megamind.avi"), FILM_FRAME + 1)?.remove(FILM_FRAME);
    let ([face_x, face_y], face_height) = PORTRAIT_FACE;
    let side = 3.0 * face_height;
    let head = (
        (face_x - side / 2.0).max(0.0) as u32,
        (face_y - side / 2.0).max(0.0) as u32,
        side as u32,
    );
    let model = gstlsydrelight::paths::default_model()
        .to_str()
        .ok_or("the default model's path is not UTF-8")?
        .to_string();
    let (cw, header) = (200u32, 100u32);
    let rows = [
        SheetRow {
            frame: person,
            shown: None,
            height: 150,
        },
        SheetRow {
            frame: portrait,
            shown: Some(head),
            height: 200,
        },
        SheetRow {
            frame: film,
            shown: None,
            height: 150,
        },
    ];
    let height = header + rows.iter().map(|r| r.height).sum::<u32>();
    let columns = 1 + Preset::ALL.len() as u32;
    let mut sheet = image::RgbImage::from_pixel(cw * columns, height, image::Rgb([24, 24, 24]));
    for (col, preset) in std::iter::once(None)
        .chain(Preset::ALL.map(Some))
        .enumerate()
    {
        let x = col as u32 * cw;
        if let Some(p) = preset {
            let monitor = to_image(&light_frame(&p.light(), 192, 96));
            image::imageops::overlay(&mut sheet, &monitor, (x + 4) as i64, 2);
        }
        let mut y = header;
        for row in &rows {
            let relit = match preset {
                None => row.frame.clone(),
                // The element's own default model: what a user gets who names only a preset.
                Some(p) => relight_still(&row.frame, |e| {
                    e.set_property("model-location", &model);
                    e.set_property("target-preset", p)
                }),
            };
            let mut shown = to_image(&relit);
            if let Some((sx, sy, side)) = row.shown {
                shown = image::imageops::crop_imm(&shown, sx, sy, side, side).to_image();
            }
            let scaled = fit(&shown, cw - 4, row.height - 4);
            image::imageops::overlay(&mut sheet, &scaled, (x + 2) as i64, (y + 2) as i64);
            y += row.height;
        }
        eprintln!("{}", preset.map_or("input", |p| p.nick()));
    }
    std::fs::create_dir_all(out.parent().unwrap()).map_err(|e| e.to_string())?;
    sheet.save(out).map_err(|e| e.to_string())
}

/// The panorama with the monitor's window at three yaws, and the three lights.
fn projection(out: &Path) -> Result<(), String> {
    let pano = outdoor_panorama(720);
    let (w, h) = (720u32, 360u32);
    let tone = linear_to_srgb_byte;
    let mut fig = image::RgbImage::from_pixel(w, h + 150, image::Rgb([24, 24, 24]));
    for y in 0..h {
        for x in 0..w {
            fig.put_pixel(
                x,
                y,
                image::Rgb(pano.pixel(x as usize, y as usize).map(tone)),
            );
        }
    }
    let views = [
        (-90.0, [255u8, 80, 80]),
        (0.0, [255, 255, 80]),
        (90.0, [80, 160, 255]),
    ];
    for (k, (yaw, colour)) in views.iter().enumerate() {
        let view = View {
            yaw: *yaw,
            ..View::default()
        };
        // The window: longitudes yaw +- fov/2, latitudes +- fov/4 (pitch 0).
        let x0 = ((yaw - view.fov / 2.0) / 360.0 + 0.5) * w as f64;
        let x1 = ((yaw + view.fov / 2.0) / 360.0 + 0.5) * w as f64;
        let y0 = (0.5 - view.fov / 4.0 / 180.0) * h as f64;
        let y1 = (0.5 + view.fov / 4.0 / 180.0) * h as f64;
        let inset = 2 * k as i64;
        let wrap = |x: i64| x.rem_euclid(w as i64) as u32;
        for x in (x0 as i64 + inset)..(x1 as i64 - inset) {
            for y in [y0 as i64 + inset, y1 as i64 - inset - 1] {
                fig.put_pixel(wrap(x), y as u32, image::Rgb(*colour));
            }
        }
        for y in (y0 as i64 + inset)..(y1 as i64 - inset) {
            for x in [x0 as i64 + inset, x1 as i64 - inset - 1] {
                fig.put_pixel(wrap(x), y as u32, image::Rgb(*colour));
            }
        }
        let light = to_image(&light_frame(&pano.light(&view), 32 * 7, 16 * 7));
        let lx = 12 + k as u32 * 236;
        for y in (h + 16)..(h + 16 + 116) {
            for x in lx..(lx + 228) {
                fig.put_pixel(x, y, image::Rgb(*colour));
            }
        }
        image::imageops::overlay(&mut fig, &light, (lx + 2) as i64, (h + 18) as i64);
    }
    std::fs::create_dir_all(out.parent().unwrap()).map_err(|e| e.to_string())?;
    fig.save(out).map_err(|e| e.to_string())
}

/// A target measured: its name, the light the truth is rendered under, and the
/// element properties that select it.
struct Measured {
    name: String,
    light: Light,
    properties: Vec<(String, String)>,
}

fn measured_targets(map: &Path) -> Vec<Measured> {
    let mut targets: Vec<_> = Preset::ALL
        .iter()
        .map(|p| Measured {
            name: format!("preset-{}", p.nick()),
            light: p.light(),
            properties: vec![("target-preset".to_string(), p.nick().to_string())],
        })
        .collect();
    let pano = Panorama::open(map).expect("the map just written");
    for yaw in [-90.0, 0.0, 90.0, 180.0] {
        targets.push(Measured {
            name: format!("outdoor-yaw{yaw}"),
            light: pano.light(&View {
                yaw,
                ..View::default()
            }),
            properties: vec![
                (
                    "target-environment".to_string(),
                    map.to_string_lossy().into_owned(),
                ),
                ("target-yaw".to_string(), format!("{yaw}")),
            ],
        });
    }
    targets
}

/// The simulator's `call` recording of `frames` frames with the exact render
/// under every preset and the outdoor map at four yaws, those lights shining
/// from `stage` (made once, kept in `target/tmp`), and those targets.
fn call_recording(frames: usize, stage: Stage) -> Result<(PathBuf, Vec<Measured>), String> {
    let suffix = if stage == Stage::Dome { "-dome" } else { "" };
    let dir = checkout().join(format!("target/tmp/targets-call-{frames}{suffix}"));
    let map = dir.join("outdoor.exr");
    write_exr(512, &map)?;
    let targets = measured_targets(&map);
    if !dir.join("meta.json").exists() {
        let mut spec = RecordingSpec::standard("call").ok_or("no call recording")?;
        spec.frames = frames;
        spec.truth_stage = stage;
        let mut rec = Recording::new(spec)?;
        for t in &targets {
            // The monitor shows the light itself: each grid cell a flat block.
            let frame = light_frame(&t.light, FRAME_WIDTH, FRAME_HEIGHT);
            let cells = light_of(rec.renderer(), &frame);
            rec.targets.push((t.name.clone(), frame, cells));
        }
        eprintln!(
            "rendering {} frames under {} lights into {}",
            frames,
            rec.targets.len(),
            dir.display()
        );
        rec.write(&dir).map_err(|e| e.to_string())?;
    }
    Ok((dir, targets))
}

/// Relights the simulator's `call` recording to every preset and to the outdoor
/// map at four yaws, and scores each against the exact render under that light;
/// with `paste_alone`, also the paste of the truth's own change where the
/// element relit (what the element would score with a perfect network).
/// `settings` are set on the element in every run, after the target's own.
fn measure(
    frames: usize,
    model: &Path,
    stage: Stage,
    paste_alone: bool,
    settings: &[(String, String)],
) -> Result<(), String> {
    let (dir, targets) = call_recording(frames, stage)?;
    let paste = paste_alone
        .then(|| PasteAlone::new(&dir, frames, model, settings))
        .transpose()?;
    let extra = if paste.is_some() {
        (
            " paste alone's RMSE | ratios to the input's (element, paste alone) |",
            "---|---|",
        )
    } else {
        ("", "")
    };
    println!(
        "| target | face-region RMSE | input's RMSE | ms/frame (under load) |{}",
        extra.0
    );
    println!("|---|---|---|---|{}", extra.1);
    let model_str = model.to_string_lossy().into_owned();
    let shipped = ["studio", "sunset", "left-key"].map(|n| (n.to_string(), Vec::new()));
    let all = shipped
        .into_iter()
        .chain(targets.into_iter().map(|t| (t.name, t.properties)));
    for (name, props) in all {
        let mut p: Vec<(&str, &str)> = vec![("model-location", &model_str)];
        p.extend(
            props
                .iter()
                .chain(settings)
                .map(|(k, v)| (k.as_str(), v.as_str())),
        );
        let s = score_recording(&dir, &name, true, &p, false)?;
        let columns = match &paste {
            Some(paste) => {
                let rmse = paste.rmse(&dir, &name)?;
                format!(
                    " {rmse:.2} | {:.2} / {:.2} |",
                    s.rmse_region / s.input_rmse_region,
                    rmse / s.input_rmse_region
                )
            }
            None => String::new(),
        };
        println!(
            "| {name} | {:.2} | {:.2} | {:.0} |{columns}",
            s.rmse_region, s.input_rmse_region, s.ms_per_frame
        );
    }
    Ok(())
}

/// The recording's face frames as the element's denoising leaves them, and
/// where the element relits them: what the paste of each target's truth needs.
struct PasteAlone {
    denoised: Vec<RgbImage>,
    relit: Vec<Option<Relit>>,
    resolution: usize,
}

impl PasteAlone {
    /// Where and how strongly the element with `model` relits the recording's
    /// face, and its frames denoised as the element denoises them before its
    /// paste. The face's box, fade and strength come from face following alone,
    /// not from the target or the monitor, so one run serves every target.
    /// `settings` as [`measure`]'s.
    fn new(
        dir: &Path,
        frames: usize,
        model: &Path,
        settings: &[(String, String)],
    ) -> Result<PasteAlone, String> {
        init();
        let input = read_y4m(&dir.join("face.y4m"), frames)?;
        let relit: Vec<_> = relight_with(
            &input,
            model,
            &format!(
                "target-location=\"{}\"{}",
                dir.join("target-studio.png").display(),
                settings
                    .iter()
                    .map(|(k, v)| format!(" {k}={v}"))
                    .collect::<String>()
            ),
            Format::Rgb,
        )?
        .into_iter()
        .map(|(_, relit)| relit)
        .collect();
        let denoised = denoised(&input.iter().map(packed).collect::<Vec<_>>(), &relit)?
            .into_iter()
            .map(unpacked)
            .collect();
        let resolution = Manifest::load(model).map_err(|e| e.to_string())?.resolution;
        Ok(PasteAlone {
            denoised,
            relit,
            resolution,
        })
    }

    /// The face-region RMSE of the truth under `target` pasted onto the input.
    fn rmse(&self, dir: &Path, target: &str) -> Result<f64, String> {
        let truth = read_y4m(
            &dir.join(format!("truth-{target}.y4m")),
            self.denoised.len(),
        )?;
        let pasted = truth_pasted(&self.denoised, &truth, &self.relit, self.resolution)?;
        Ok(face_region_rmse(&pasted, &truth))
    }
}

/// What target changes and video targets cost.
fn timing() -> Result<(), String> {
    lsydrelight_testkit::init();
    let reps = 20;
    let started = Instant::now();
    for _ in 0..reps {
        for p in Preset::ALL {
            std::hint::black_box(p.light());
        }
    }
    let preset_ms = started.elapsed().as_secs_f64() * 1e3 / (reps * Preset::ALL.len()) as f64;
    let map = checkout().join("target/tmp/targets-timing/outdoor-2048.exr");
    write_exr(2048, &map)?;
    let started = Instant::now();
    let pano = Panorama::open(&map)?;
    let open_ms = started.elapsed().as_secs_f64() * 1e3;
    let time_view = |view: View| {
        let started = Instant::now();
        for _ in 0..5 {
            std::hint::black_box(pano.light(&view));
        }
        started.elapsed().as_secs_f64() * 1e3 / 5.0
    };
    let level_ms = time_view(View {
        yaw: 30.0,
        ..View::default()
    });
    let pitched_ms = time_view(View {
        yaw: 30.0,
        pitch: 10.0,
        ..View::default()
    });
    println!("| step | ms |");
    println!("|---|---|");
    println!("| a preset's light | {preset_ms:.3} |");
    println!("| reading a 2048 x 1024 EXR map | {open_ms:.0} |");
    println!("| projecting it, no pitch (a yaw change) | {level_ms:.1} |");
    println!("| projecting it, with pitch | {pitched_ms:.1} |");

    // In the element: a fade (one encode a frame) and a video target (one light and
    // one encode per new frame of it), against the same frames with a still target.
    let person = render_person(&State::default(), Vec3::new(0.8, 0.8, 0.8), 320, 240);
    let c = rgb_caps(320, 240, 30);
    let frames = 60u64;
    let run = |fade: bool, video: bool| -> (f64, f64, u64, f64, u64) {
        let e = element();
        e.set_property("reuse-interval", 1u32);
        let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
        h.set_src_caps(c.clone());
        // The target video comes from its own thread: each face frame waits for the
        // target frame after its time, as with any aligned stream.
        let pusher = video.then(|| {
            let mut th = Harness::with_element(&e, Some("target_sink"), None);
            let tc = rgb_caps(256, 144, 30);
            th.set_src_caps(tc.clone());
            std::thread::spawn(move || {
                for i in 0..frames {
                    let level = (i % 10) as f32 / 10.0;
                    let light = Light::uniform([level, 0.5, 1.0 - level]);
                    let frame = light_frame(&light, 256, 144);
                    if th.push(buffer(&frame, &tc, frame_time(i), FRAME)).is_err() {
                        break;
                    }
                }
                th.push_event(gst::event::Eos::new());
                th
            })
        });
        for i in 0..frames {
            if fade && i % 15 == 0 {
                e.set_property("target-preset", Preset::ALL[(i / 15) as usize % 9]);
            }
            h.push(buffer(&person, &c, frame_time(i), FRAME)).unwrap();
            h.pull().unwrap();
        }
        if let Some(p) = pusher {
            p.join().unwrap();
        }
        let st = e.property::<gst::Structure>("stats");
        let f = |k: &str| st.get::<f64>(k).unwrap();
        (
            f("processing-seconds") * 1e3 / frames as f64,
            f("target-seconds") * 1e3,
            stat(&e, "target-encodes"),
            (f("target-stream-light-seconds") + f("target-stream-arrival-seconds")) * 1e3,
            stat(&e, "target-stream-decoded") + stat(&e, "target-stream-arrival-decoded"),
        )
    };
    let (still, ..) = run(false, false);
    let (faded, fade_ms, fade_encodes, ..) = run(true, false);
    let (video, video_enc_ms, video_encodes, light_ms, decoded) = run(false, true);
    println!("| element, still target: per frame | {still:.1} |");
    println!("| element, a new preset every 0.5 s (always fading): per frame | {faded:.1} |");
    println!(
        "| encoding a faded light | {:.2} ({fade_encodes} encodes) |",
        fade_ms / fade_encodes.max(1) as f64
    );
    println!("| element, a 30 fps video target: per frame | {video:.1} |");
    println!(
        "| a video target frame's light (256 x 144) | {:.2} |",
        light_ms / decoded.max(1) as f64
    );
    println!(
        "| encoding a video target frame's light | {:.2} ({video_encodes} encodes) |",
        video_enc_ms / video_encodes.max(1) as f64
    );
    Ok(())
}
