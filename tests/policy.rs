//! The per-frame policy without GStreamer: which frames are relit, reused or
//! passed through, and what each leaves of the stream's state.

use deskstage::math::Vec3;
use deskstage::monitor::RgbImage;
use gstlsydrelight::engine::{
    self, Action, FramePolicy, FrameRequest, PassThrough, Provider, Relighter, Reuse, Skips,
    Source, Temporal,
};
use gstlsydrelight::frame::{
    Crop, FacePlace, Frame, FrameMut, LightingChange, PixelFormat, YuvMatrix,
};
use gstlsydrelight::light::Light;
use gstlsydrelight::paths;
use gstlsydrelight::targets::Preset;
use lsydrelight_testkit::{
    default_model,
    person::{face_rgb, render_face},
};

fn target() -> Light {
    Light::uniform([0.8, 0.6, 0.4])
}

fn policy(skips: Skips) -> FramePolicy {
    let env = engine::environment(&paths::default_ort_library())
        .expect("ONNX Runtime loads (run scripts/setup.sh)");
    let network =
        Relighter::new(env, &default_model(), 1, Provider::Cpu).expect("the shipped model loads");
    let mut p = FramePolicy::new(network, Temporal::default(), skips);
    p.set_target(&target()).unwrap();
    p
}

/// What the policy does with `image` as a face frame; its change, if any, as bytes
/// pasted onto a copy of the frame.
fn run(
    p: &mut FramePolicy,
    image: &RgbImage,
    source: Source,
    late: bool,
) -> (Action, Option<Vec<u8>>) {
    run_faded(p, image, source, late, 1.0)
}

/// [`run`] with the face shown at `strength`.
fn run_faded(
    p: &mut FramePolicy,
    image: &RgbImage,
    source: Source,
    late: bool,
    strength: f32,
) -> (Action, Option<Vec<u8>>) {
    let (w, h) = (image.width, image.height);
    let frame = Frame::packed_rgb(&image.data, w, h);
    let crop = Crop::centred(w, h, 0.5, 0.5, 1.0);
    let outcome = p
        .process(FrameRequest {
            frame: &frame,
            crop,
            face: FacePlace::default(),
            strength,
            source,
            late,
            want_prediction: false,
        })
        .unwrap();
    let pasted = outcome
        .change
        .map(|change| paste(image, crop, change, outcome.strength));
    (outcome.action, pasted)
}

/// `change` pasted onto a copy of `image` round `crop`, as bytes.
fn paste(image: &RgbImage, crop: Crop, change: &LightingChange, strength: f32) -> Vec<u8> {
    let (w, h) = (image.width, image.height);
    let mut out = image.data.clone();
    let mut fm = FrameMut {
        format: PixelFormat::Rgb,
        width: w,
        height: h,
        planes: [
            (&mut out[..], w * 3),
            (Default::default(), 0),
            (Default::default(), 0),
        ],
        matrix: YuvMatrix::BT601_LIMITED,
    };
    change.apply_faded(&mut fm, crop, 0, strength);
    out
}

fn solid(like: &RgbImage, level: u8) -> RgbImage {
    RgbImage {
        width: like.width,
        height: like.height,
        data: vec![level; like.data.len()],
    }
}

fn white_monitor() -> Source {
    Source::Known(Light::uniform([1.0; 3]))
}

#[test]
fn black_and_nearly_black_frames_pass_through_and_forget_the_past() {
    let mut p = policy(Skips::default());
    let face = face_rgb();
    assert_eq!(run(&mut p, face, white_monitor(), false).0, Action::Relit);
    for level in [0, 3] {
        let (action, change) = run(&mut p, &solid(face, level), white_monitor(), false);
        assert_eq!(
            action,
            Action::PassedThrough(PassThrough::Dark),
            "level {level}"
        );
        assert!(change.is_none(), "a dark frame is left as it is");
    }
    // The stream's state was forgotten once, at the first dark frame.
    assert_eq!(p.counts().resets, 1);
    assert_eq!(p.counts().passed_dark, 2);
    // The next frame starts afresh: the same as a new stream's first frame.
    let after = run(&mut p, face, white_monitor(), false).1.unwrap();
    let fresh = run(&mut policy(Skips::default()), face, white_monitor(), false)
        .1
        .unwrap();
    assert!(
        after == fresh,
        "the frame after the dark ones is not a fresh start"
    );
}

#[test]
fn late_frames_reuse_the_last_relighting_once_there_is_one() {
    let mut p = policy(Skips::default());
    let face = face_rgb();
    // Nothing to reuse yet: even a late frame is relit.
    let (first, relit) = run(&mut p, face, white_monitor(), true);
    assert_eq!(first, Action::Relit);
    let (late, reused) = run(&mut p, face, white_monitor(), true);
    assert_eq!(late, Action::Reused(Reuse::Late));
    assert!(reused == relit, "the reused change is the last one");
    assert_eq!(p.counts().reused_late, 1);
    assert_eq!(p.counts().relit, 1);
}

#[test]
fn a_source_light_equal_to_the_target_passes_through() {
    let mut p = policy(Skips::default());
    let (action, change) = run(&mut p, face_rgb(), Source::Known(target()), false);
    assert_eq!(action, Action::PassedThrough(PassThrough::SameLight));
    assert!(change.is_none());
    let mut always = policy(Skips {
        skip_same_light: false,
        ..Skips::default()
    });
    assert_eq!(
        run(&mut always, face_rgb(), Source::Known(target()), false).0,
        Action::Relit
    );
}

#[test]
fn only_a_reset_that_forgets_something_counts() {
    let mut p = policy(Skips::default());
    assert!(!p.reset(), "a new stream has nothing to forget");
    run(&mut p, face_rgb(), Source::Unknown, false);
    assert!(p.reset());
    assert!(!p.reset());
    assert_eq!(p.counts().resets, 1);
    assert!(p.smoothed_features().is_none());
}

#[test]
fn the_network_runs_every_reuse_interval_frames_and_at_once_on_a_change() {
    let mut p = policy(Skips {
        reuse_interval: 3,
        ..Skips::default()
    });
    let face = face_rgb();
    let runs: Vec<(Action, Option<Vec<u8>>)> = (0..7)
        .map(|_| run(&mut p, face, white_monitor(), false))
        .collect();
    let actions: Vec<Action> = runs.iter().map(|(a, _)| *a).collect();
    let (relit, carried) = (Action::Relit, Action::Reused(Reuse::Interval));
    assert_eq!(
        actions,
        [relit, carried, carried, relit, carried, carried, relit]
    );
    // The same picture: the carried change is the relit one.
    assert!(runs[1].1 == runs[0].1, "carried change differs");
    // Another picture (a cut) runs the network at once, and the interval starts again.
    let cut = render_face(Vec3::new(0.3, 0.3, 1.0));
    assert_eq!(run(&mut p, &cut, white_monitor(), false).0, relit);
    assert_eq!(run(&mut p, &cut, white_monitor(), false).0, carried);
    // So does another light.
    let blue = Source::Known(Light::uniform([0.1, 0.1, 0.9]));
    assert_eq!(run(&mut p, &cut, blue, false).0, relit);
    // An interval of 1 runs the network on every frame.
    let mut every = policy(Skips {
        reuse_interval: 1,
        ..Skips::default()
    });
    for _ in 0..3 {
        assert_eq!(run(&mut every, face, white_monitor(), false).0, relit);
    }
}

#[test]
fn a_still_screen_encodes_its_light_once_it_has_settled() {
    let mut p = policy(Skips {
        reuse_interval: 1,
        ..Skips::default()
    });
    let face = face_rgb();
    let encodes = |p: &mut FramePolicy, source: &Source, frames: usize| {
        for _ in 0..frames {
            assert_eq!(run(p, face, source.clone(), false).0, Action::Relit);
        }
        p.counts().source_encodes
    };
    // The averaged light settles within the averaging window; from then on the
    // same screen gives the same light, whose code is reused.
    let settled = encodes(&mut p, &white_monitor(), 4);
    assert!(settled >= 1);
    assert_eq!(encodes(&mut p, &white_monitor(), 4), settled);
    // Another screen is encoded afresh.
    let blue = Source::Known(Light::uniform([0.1, 0.1, 0.9]));
    assert!(encodes(&mut p, &blue, 1) > settled);
}

#[test]
fn without_a_face_the_frame_passes_and_a_fading_face_is_shown_in_part() {
    let mut p = policy(Skips::default());
    let face = face_rgb();
    assert_eq!(run(&mut p, face, white_monitor(), false).0, Action::Relit);
    let (action, change) = run_faded(&mut p, face, white_monitor(), false, 0.0);
    assert_eq!(action, Action::PassedThrough(PassThrough::NoFace));
    assert!(change.is_none());
    assert_eq!(
        p.counts().resets,
        1,
        "a lost face forgets the stream's state"
    );
    // Half faded in: the change is shown at half its log gain, so every byte
    // moves the same way as when fully shown and no farther, and on average
    // about half as far.
    let mut full = policy(Skips::default());
    let shown = run(&mut full, face, white_monitor(), false).1.unwrap();
    let mut half = policy(Skips::default());
    let halfway = run_faded(&mut half, face, white_monitor(), false, 0.5)
        .1
        .unwrap();
    let (mut full_total, mut half_total) = (0.0, 0.0);
    for ((s, h), i) in shown.iter().zip(&halfway).zip(&face.data) {
        let (full_step, half_step) = (*s as f32 - *i as f32, *h as f32 - *i as f32);
        // A level either way for the dither and rounding.
        assert!(
            half_step.abs() <= full_step.abs() + 1.0,
            "{half_step} {full_step}"
        );
        assert!(half_step * full_step >= -1.0, "{half_step} {full_step}");
        (full_total, half_total) = (full_total + full_step.abs(), half_total + half_step.abs());
    }
    let share = half_total / full_total;
    assert!(
        (0.35..0.65).contains(&share),
        "half faded in moves {share} as far"
    );
}

#[test]
fn the_network_gives_the_same_beside_other_work_on_the_frame() {
    // The element denoises the frame on another thread while the network
    // runs: prepare, then finish_while, must relight as process does.
    let face = face_rgb();
    let (w, h) = (face.width, face.height);
    let frame = Frame::packed_rgb(&face.data, w, h);
    let crop = Crop::centred(w, h, 0.5, 0.5, 1.0);
    let request = || FrameRequest {
        frame: &frame,
        crop,
        face: FacePlace::default(),
        strength: 1.0,
        source: white_monitor(),
        late: false,
        want_prediction: false,
    };
    let every_frame = Skips {
        reuse_interval: 1,
        ..Skips::default()
    };
    let (mut alone, mut beside) = (policy(every_frame), policy(every_frame));
    for _ in 0..3 {
        let expected = alone.process(request()).unwrap();
        let engine::Prepared::Relight(pending) = beside.prepare(request()).unwrap() else {
            panic!("every frame runs the network at reuse interval 1");
        };
        let here = std::thread::current().id();
        let (outcome, elsewhere, _) =
            beside.finish_while(pending, || std::thread::current().id() != here);
        let outcome = outcome.unwrap();
        assert!(elsewhere, "the other work runs on another thread");
        assert_eq!(outcome.action, Action::Relit);
        let pasted = |change| paste(face, crop, change, 1.0);
        assert!(
            pasted(outcome.change.unwrap()) == pasted(expected.change.unwrap()),
            "the same change"
        );
    }
}

/// The preset `warm-key-left`: a warm key in the screen's left third.
fn warm_key_left() -> Light {
    Preset::WarmKeyLeft.light()
}

/// How much warmer (ln of red over blue, means over the image) `out` is than `input`.
fn warming(input: &RgbImage, out: &[u8]) -> f64 {
    let warmth = |data: &[u8]| {
        let mean = |c: usize| {
            data.iter()
                .skip(c)
                .step_by(3)
                .map(|&v| v as f64)
                .sum::<f64>()
                / (data.len() / 3) as f64
        };
        (mean(0) / mean(2)).ln()
    };
    warmth(out) - warmth(&input.data)
}

/// Relit to a key light on part of the screen, the face takes the key's colour
/// from the key spread evenly (a second decode every fourth network frame): it
/// ends warmer than with `spread-colour` off, where the network alone gives
/// too little of it. An even target needs no second decode.
#[test]
fn a_key_light_colours_the_face_by_its_mean_with_a_second_decode_every_fourth_frame() {
    let face = face_rgb();
    let relit = |spread_colour: bool, target: &Light| {
        let mut p = policy(Skips {
            reuse_interval: 1,
            ..Skips::default()
        });
        p.set_spread_colour(spread_colour);
        p.set_target(target).unwrap();
        let mut last = None;
        for _ in 0..8 {
            let dim_grey = Source::Known(Light::uniform([0.1; 3]));
            let (action, pasted) = run(&mut p, face, dim_grey, false);
            assert_eq!(action, Action::Relit);
            last = pasted;
        }
        (warming(face, &last.unwrap()), p.counts().spread_decodes)
    };
    let (spread, spread_decodes) = relit(true, &warm_key_left());
    let (own, own_decodes) = relit(false, &warm_key_left());
    assert_eq!((spread_decodes, own_decodes), (2, 0));
    assert!(
        spread > 1.3 * own && own > 0.0,
        "warming with the key spread evenly {spread:.3}, by the network alone {own:.3}"
    );
    assert_eq!(
        relit(true, &target()).1,
        0,
        "an even target is its own spread"
    );
}

/// A target fading in small steps (or a video target's next frame) keeps the
/// colour difference, so it costs no more second decodes than a still target;
/// a jump to another light decodes the spread at once.
#[test]
fn a_fading_target_keeps_the_colour_difference_and_a_new_one_decodes_at_once() {
    let mut p = policy(Skips {
        reuse_interval: 1,
        ..Skips::default()
    });
    let key = warm_key_left();
    let dimmed = |by: f32| Light(key.0.iter().map(|v| v * (1.0 - by)).collect());
    let face = face_rgb();
    let dim_grey = || Source::Known(Light::uniform([0.1; 3]));
    for i in 0..8 {
        p.set_target(&dimmed(0.01 * i as f32)).unwrap();
        assert_eq!(run(&mut p, face, dim_grey(), false).0, Action::Relit);
    }
    assert_eq!(
        p.counts().spread_decodes,
        2,
        "every 4th frame, as for a still target"
    );
    let mirrored = Light(
        key.0
            .chunks_exact(gstlsydrelight::light::LIGHT_COLS)
            .flat_map(|row| row.iter().rev().copied())
            .collect(),
    );
    p.set_target(&mirrored).unwrap();
    assert_eq!(run(&mut p, face, dim_grey(), false).0, Action::Relit);
    assert_eq!(
        p.counts().spread_decodes,
        3,
        "a key from the other side decodes at once"
    );
}
