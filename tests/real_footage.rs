//! The lighting change on faces the model never saw, with no monitor stream,
//! the face followed and the element's default model (the defaults), scored
//! with the measures that need no ground truth (`lsydrelight_testkit::quality`):
//! no box edge, no colour blotches, no breathing brightness. The real media are
//! fetched by `scripts/setup.sh full` into `target/real-media`; without them
//! those tests say so and pass. `examples/real_footage` prints the same
//! measures over 90 frames. The element is fed packed RGB and, as webcams
//! deliver frames, I420, with its defaults: its denoising on, so the measures
//! compare the output with the input as the denoising left it
//! (`footage::denoised`). I420 is read as it carries light and colour
//! (`quality::View`).

use std::path::PathBuf;

use deskstage::monitor::RgbImage;
use lsydrelight_testkit::{
    checkout,
    direction::{LightShape, light_shape},
    footage::{
        Format, Relit, decode, denoised, portrait_720p, portrait_720p_leaning, read_y4m, relight,
        relight_with, small_portrait_1080p, through,
    },
    init,
    quality::{Region, SquareMeans, View, box_edges, mean_level, mottling, pumping},
    recording::ensure_recording,
};

/// A real clip fetched by `scripts/setup.sh full`, or None (with a message)
/// where it has not been fetched.
fn media(name: &str) -> Option<PathBuf> {
    let path = checkout().join("target/real-media").join(name);
    if !path.exists() {
        eprintln!(
            "SKIPPED: {} is missing; run scripts/setup.sh full, which fetches it",
            path.display()
        );
        return None;
    }
    Some(path)
}

/// The folder of the real media when it holds the portrait, for the
/// testkit's framings of it, or None (with a message).
fn portrait_media() -> Option<PathBuf> {
    media("astronaut.png").map(|path| path.parent().expect("the media folder").to_path_buf())
}

/// One frame's measures.
struct Measures {
    box_edge: f64,
    /// The box edge where the picture itself has no edge ([`box_edges`]).
    unexplained_box_edge: f64,
    /// Over the square the element relit (its part inside the frame).
    mottling: f64,
    /// Over the face within it ([`Relit::face`]), as issue 12 defines it.
    face_mottling: f64,
    /// The relit square's mean levels, and whether the change was fading.
    means: SquareMeans,
}

/// Per frame, the element fed `format` with its defaults: its output
/// against what its lighting change was applied to (the input it was fed, as
/// the denoising left it), over the square the element relit (the centred
/// full-height square where it marked none).
fn measure(input: &[RgbImage], target: PathBuf, format: Format) -> Vec<Measures> {
    let model = gstlsydrelight::paths::default_model();
    let (output, relits): (Vec<_>, Vec<_>) = relight(input, &model, &target, format, true)
        .unwrap()
        .into_iter()
        .unzip();
    let changed = denoised(&through(input, format).unwrap(), &relits).unwrap();
    changed
        .iter()
        .zip(output)
        .zip(relits)
        .map(|((i, o), relit)| {
            let fading = relit.as_ref().is_some_and(Relit::fading);
            let (region, face) = relit.map(|r| (r.region, r.face)).unwrap_or_else(|| {
                let size = i.width.min(i.height);
                let square = Region {
                    x: (i.width - size) / 2,
                    y: (i.height - size) / 2,
                    size,
                };
                (square, square.face_within())
            });
            let (i, o) = (i.frame(), o.frame());
            let (colour_in, colour_out) = (View::colour(i), View::colour(o));
            let edges = box_edges(&View::brightness(i), &View::brightness(o));
            Measures {
                box_edge: edges.all.score,
                unexplained_box_edge: edges.unexplained.score,
                mottling: mottling(&colour_in, &colour_out, region),
                face_mottling: mottling(&colour_in, &colour_out, face),
                means: SquareMeans {
                    input: mean_level(&colour_in, region),
                    output: mean_level(&colour_out, region),
                    fading,
                },
            }
        })
        .collect()
}

fn sunset() -> PathBuf {
    checkout().join("models/targets/sunset.png")
}

fn largest(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, f64::max)
}

fn median(v: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = v.collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn a_real_portrait_is_relit_without_a_box_or_blotches() {
    init();
    let Some(path) = media("astronaut.png") else {
        return;
    };
    // A still: a few frames let the face be found and the light settle.
    let m = measure(&decode(&path, 12).unwrap(), sunset(), Format::Rgb);
    let last = m.last().unwrap();
    // `cargo run --release --example benchmark -- --quality` over 90 frames:
    // 4.7% (25.7% in all) and 0.63%.
    assert!(
        last.unexplained_box_edge < 10.0,
        "box edge {:.1}% where the picture has none ({:.1}% in all)",
        last.unexplained_box_edge,
        last.box_edge
    );
    assert!(last.mottling < 2.0, "mottling {:.2}%", last.mottling);
    // Over the face alone, the definition: 1.07% over 90 frames
    // (1.18% counting the near-black pixels; `quality::MOTTLING_BLACK`).
    assert!(
        last.face_mottling < 2.0,
        "mottling over the face {:.2}%",
        last.face_mottling
    );
}

#[test]
fn a_film_clip_is_relit_without_a_box_or_pumping() {
    init();
    let Some(path) = media("Megamind.avi") else {
        return;
    };
    let m = measure(&decode(&path, 90).unwrap(), sunset(), Format::Rgb);
    let box_edge = largest(m.iter().map(|m| m.box_edge));
    let unexplained = largest(m.iter().map(|m| m.unexplained_box_edge));
    let mottled = median(m.iter().map(|m| m.mottling));
    let pumped = pumping(&m.iter().map(|m| m.means).collect::<Vec<_>>());
    // 8.3% (28.1% in all), 1.24% and 0.31 levels over 90 frames
    // (`benchmark --quality`; the element before 2026-12-08 read 0.93 levels
    // counting the face's fade-in, which `pumping` now leaves out). Over the whole relit square the mottling is
    // mostly the dark clip's hair and room just above black, so its bar is
    // looser than the face's.
    assert!(
        unexplained < 10.0,
        "box edge {unexplained:.1}% where the picture has none ({box_edge:.1}% in all)"
    );
    assert!(pumped < 0.6, "pumping {pumped:.2} levels");
    assert!(mottled < 3.0, "mottling {mottled:.2}%");
    // Over the face alone, the bar: 1.00% over 90 frames (1.37% in all).
    let face_mottled = median(m.iter().map(|m| m.face_mottling));
    assert!(
        face_mottled < 2.0,
        "mottling over the face {face_mottled:.2}%"
    );
}

#[test]
fn a_real_portrait_in_i420_takes_the_change_each_pixel_would_in_rgb() {
    init();
    let Some(path) = media("astronaut.png") else {
        return;
    };
    let m = measure(&decode(&path, 12).unwrap(), sunset(), Format::I420);
    let last = m.last().unwrap();
    // 4.7% (24.6% in all), 0.75% and over the face 0.79% over 90 frames
    // (`benchmark --quality`, read as I420 carries them).
    assert!(
        last.unexplained_box_edge < 10.0,
        "box edge {:.1}% where the picture has none ({:.1}% in all)",
        last.unexplained_box_edge,
        last.box_edge
    );
    assert!(last.mottling < 2.0, "mottling {:.2}%", last.mottling);
    assert!(
        last.face_mottling < 2.0,
        "mottling over the face {:.2}%",
        last.face_mottling
    );
}

#[test]
fn a_film_clip_in_i420_is_relit_as_in_rgb() {
    init();
    let Some(path) = media("Megamind.avi") else {
        return;
    };
    let m = measure(&decode(&path, 90).unwrap(), sunset(), Format::I420);
    let box_edge = largest(m.iter().map(|m| m.box_edge));
    let unexplained = largest(m.iter().map(|m| m.unexplained_box_edge));
    let face_mottled = median(m.iter().map(|m| m.face_mottling));
    let pumped = pumping(&m.iter().map(|m| m.means).collect::<Vec<_>>());
    // 9.3% (27.8% in all), 4.24% and 0.29 levels over 90 frames (the element
    // before 2026-12-08 read 0.94 counting the face's fade-in, which
    // `pumping` now leaves out). Read through
    // 8-bit RGB, the
    // box edge was 28.8%: the clipping of near-black pixels that share a
    // chroma sample with brighter ones. Over the face, mottling is the
    // rounding of chroma on this dark clip's dark pixels, one chroma sample
    // for four pixels (6.16% counting those under 16 levels too), which the
    // measure allows for in 8-bit RGB but not in Y'CbCr; this bound
    // holds the measured figure.
    assert!(
        unexplained < 10.0,
        "box edge {unexplained:.1}% where the picture has none ({box_edge:.1}% in all)"
    );
    assert!(
        face_mottled < 4.5,
        "mottling over the face {face_mottled:.2}%"
    );
    assert!(pumped < 0.6, "pumping {pumped:.2} levels");
}

#[test]
fn a_person_walking_about_the_simulated_room_is_relit_without_a_box() {
    init();
    let dir = checkout().join("target/recordings/wander-45");
    ensure_recording(&dir, "wander", 45).unwrap();
    let frames = read_y4m(&dir.join("face.y4m"), 45).unwrap();
    let m = measure(&frames, dir.join("target-sunset.png"), Format::Rgb);
    let box_edge = largest(m.iter().map(|m| m.box_edge));
    let unexplained = largest(m.iter().map(|m| m.unexplained_box_edge));
    let mottled = median(m.iter().map(|m| m.mottling));
    let pumped = pumping(&m.iter().map(|m| m.means).collect::<Vec<_>>());
    // 7.9% (14.0% in all), 0.62% and 0.29 levels (`benchmark --quality`);
    // 9.7% where the picture has none with the face's shading clamped
    // (`plugin/frame/change.rs`).
    assert!(
        unexplained < 10.0,
        "box edge {unexplained:.1}% where the picture has none ({box_edge:.1}% in all)"
    );
    assert!(mottled < 2.0, "mottling {mottled:.2}%");
    assert!(pumped < 0.6, "pumping {pumped:.2} levels");
}

#[test]
fn a_real_portrait_relit_to_neon_changes_visibly() {
    // A relighting must show. The astronaut's face, framed as a 720p webcam
    // would (her hair near the top edge), relit to `neon` by the starter
    // model: 19.5% (RMS of the change over the face, `examples/target_lights
    // direction`; 16.4% before the face's finest shading passed, 2026-12-08)
    // with the default source, which adds the target's light to the light the
    // starter guesses is on her face; 14.8% with `source-preset=soft-front`,
    // which replaces a frontal light (measured before 2026-12-08). While her box came from the
    // whole frame, coarse (`face::search`), the starter guessed a bright
    // screen and the default source gave 3.0%. (Until the element said where
    // the face is in a square moved down into the frame, the face was
    // measured 0.67 face heights too low, over chin, neck and collar: 12.3%
    // there.) A saturated two-sided light lights the face's sides
    // differently, but not by more than it lights the face.
    init();
    let Some(folder) = portrait_media() else {
        return;
    };
    let frames = vec![portrait_720p(&folder).unwrap(); 8];
    let (_, added) = relit_to(&frames, "neon", "");
    assert!(added.strength > 8.0, "{added:?}");
    assert!(added.asymmetry.abs() < added.strength, "{added:?}");
    let (_, replaced) = relit_to(&frames, "neon", "source-preset=soft-front");
    assert!(replaced.strength > 6.0, "{replaced:?}");
    assert!(replaced.asymmetry.abs() < replaced.strength, "{replaced:?}");
}

#[test]
fn a_key_from_the_left_and_one_from_the_right_light_a_real_face_differently() {
    // `warm-key-left` stands on the person's left, the image's right; the
    // simulator's exact truth brightens the image-right half by 26.1% more
    // under it than under `cool-key-right` (key swap -26.1,
    // `examples/target_lights direction`). The element draws the side with
    // that sign on real faces: -10.2 on the portrait and -14.2 on the film clip
    // (median over 30 frames; the portrait -10.3 over this test's 8, the film
    // clip -10.0 over its 12; before the face's finest shading passed over its
    // box, 2026-12-08, -8.4 / -10.9 over 30, the film clip -7.4 over 12); the
    // release before
    // 2026-12-06, whose starter was trained on lights within a monitor's
    // width only, drew -0.8 and -4.9, and the starter of dfd58a9, whose last
    // stage left the dome's side lights out, -4.5 on the portrait.
    init();
    let (Some(folder), Some(film)) = (portrait_media(), media("Megamind.avi")) else {
        return;
    };
    let still = vec![portrait_720p(&folder).unwrap(); 8];
    let clip = decode(&film, 12).unwrap();
    for (name, frames, bar) in [("portrait", still, -9.0), ("film clip", clip, -8.5)] {
        let asymmetry = |preset| relit_to(&frames, preset, "").1.asymmetry;
        let swap = asymmetry("warm-key-left") - asymmetry("cool-key-right");
        eprintln!("{name}: key swap {swap:+.1}");
        assert!(swap < bar, "{name}: key swap {swap:+.1}, bar {bar}");
    }
}

#[test]
fn a_real_face_leaning_in_and_out_keeps_its_light() {
    // A webcam user leans towards the camera and back. The light the element
    // relights from is read off the network's crop, which the face's box
    // sets; in the whole 720p frame the portrait's box switched between about
    // 186 and 137 px as she leaned by 6%, and over these frames the mean
    // change over her face under `warm-key-left` went from -14.2% to +5.9%
    // and back: a face breathing with the distance. Looked at closer
    // (`face::search`), her box keeps its size, and the change +5.9% to +9.1%.
    init();
    let Some(folder) = portrait_media() else {
        return;
    };
    let frames: Vec<RgbImage> = (0..75)
        .map(|t| {
            let lean = 1.0 + 0.06 * (std::f32::consts::TAU * t as f32 / 60.0).sin();
            portrait_720p_leaning(&folder, lean).unwrap()
        })
        .collect();
    // After the face's fade-in of 15 frames.
    let means: Vec<f64> = relit_shapes(&frames, "warm-key-left", "")
        .into_iter()
        .skip(15)
        .map(|relit| relit.expect("her face is followed").1.mean)
        .collect();
    let (lo, hi) = (
        means.iter().copied().fold(f64::MAX, f64::min),
        means.iter().copied().fold(f64::MIN, f64::max),
    );
    eprintln!("leaning: mean change over her face {lo:+.1}% to {hi:+.1}%");
    assert!(
        hi - lo < 5.0,
        "her face's mean change spans {lo:+.1}% to {hi:+.1}%"
    );
}

#[test]
fn a_small_face_off_centre_in_1080p_is_found_and_relit() {
    // A face a tenth of the frame's height is 7 pixels tall in the face
    // detector's view of the whole 1080p frame, too small for it: the element
    // passed it through untouched. The detector's scan of tiles finds it
    // (`gstlsydrelight::face::search`), and the face is relit.
    init();
    let Some(folder) = portrait_media() else {
        return;
    };
    let (frame, face, height) = small_portrait_1080p(&folder, 0.10, [0.8, 0.3]).unwrap();
    let (shown, shape) = relit_to(&vec![frame; 60], "neon", "");
    let region = shown.face;
    let centre = [region.x, region.y].map(|c| (c + region.size / 2) as f32);
    assert!(
        (centre[0] - face[0]).hypot(centre[1] - face[1]) < 0.5 * height,
        "relit round {centre:?}, the face is at {face:?}"
    );
    assert!(
        shown.shown.is_some_and(|(strength, _)| strength > 0.99),
        "{shown:?}"
    );
    assert!(shape.strength > 5.0, "{shape:?}");
}

/// `frames` relit to `preset` by the element with the default model and its
/// other `properties`, fed RGB: how the element showed the last frame's face,
/// and the shape of the change there against the input as the element's
/// denoising saw it.
fn relit_to(frames: &[RgbImage], preset: &str, properties: &str) -> (Relit, LightShape) {
    relit_shapes(frames, preset, properties)
        .pop()
        .flatten()
        .expect("the face is found and relit")
}

/// [`relit_to`] for every frame: how the element showed each frame's face
/// and the shape of its change there, None where it relit no face.
fn relit_shapes(
    frames: &[RgbImage],
    preset: &str,
    properties: &str,
) -> Vec<Option<(Relit, LightShape)>> {
    let model = gstlsydrelight::paths::default_model();
    let relit = relight_with(
        frames,
        &model,
        &format!("target-preset={preset} target-transition=0 {properties}"),
        Format::Rgb,
    )
    .unwrap();
    let input = denoised(
        &through(frames, Format::Rgb).unwrap(),
        &relit.iter().map(|(_, r)| *r).collect::<Vec<_>>(),
    )
    .unwrap();
    relit
        .iter()
        .zip(&input)
        .map(|((output, shown), input)| {
            shown.map(|shown| {
                let shape = light_shape(
                    &View::pixels(input.frame()),
                    &View::pixels(output.frame()),
                    shown.face,
                );
                (shown, shape)
            })
        })
        .collect()
}
