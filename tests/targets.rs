//! Every kind of target light through the element: presets, environment maps
//! (with their view animated by GstController), and the crossfade that turns a
//! target change into a fade over `target-transition` instead of a jump.

use gst::prelude::*;
use gst_check::Harness;
use gst_controller::prelude::*;
use lsydrelight_testkit::{
    element::{element, stat},
    person::{FACE_H, FACE_W, face_rgb},
    target,
    video::{FRAME, buffer, caps, frame_time, mean_abs_diff, to_rgb},
};

use deskstage::monitor::RgbImage;

/// A face-pad harness on RGB frames, feature smoothing off so each frame shows
/// its own target, and the given setup applied before the element starts.
fn harness_with(setup: impl FnOnce(&gst::Element)) -> (gst::Element, Harness, gst::Caps) {
    let e = element();
    e.set_property("alpha", 1.0f32);
    setup(&e);
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    (e, h, c)
}

fn relight(h: &mut Harness, c: &gst::Caps, i: u64) -> RgbImage {
    h.push(buffer(face_rgb(), c, frame_time(i), FRAME)).unwrap();
    to_rgb(&h.pull().unwrap(), c)
}

/// The simulated person's face in the 320 x 240 test frames: columns and rows.
const FACE_X: std::ops::Range<usize> = 120..200;
const FACE_Y: std::ops::Range<usize> = 60..190;

/// Mean of channel `ch` over the face, in levels.
fn face_channel(img: &RgbImage, ch: usize) -> f64 {
    let mut sum = 0.0;
    for y in FACE_Y {
        for x in FACE_X {
            sum += img.data[3 * (y * img.width + x) + ch] as f64;
        }
    }
    sum / (FACE_X.len() * FACE_Y.len()) as f64
}

/// How much redder than blue the face is, in levels.
fn warmth(img: &RgbImage) -> f64 {
    face_channel(img, 0) - face_channel(img, 2)
}

/// The face's mean level, all channels.
fn mean(img: &RgbImage) -> f64 {
    (0..3).map(|ch| face_channel(img, ch)).sum::<f64>() / 3.0
}

#[test]
fn presets_are_listed_and_relight_as_named() {
    let e = element();
    let pspec = e.find_property("target-preset").expect("target-preset");
    let class = glib::EnumClass::with_type(pspec.value_type()).unwrap();
    let nicks: Vec<&str> = class.values().iter().map(|v| v.nick()).collect();
    for nick in [
        "none",
        "soft-front",
        "warm-key-left",
        "cool-key-right",
        "rim",
        "sunset",
        "office",
        "overcast",
        "candle",
        "neon",
    ] {
        assert!(nicks.contains(&nick), "{nick} in {nicks:?}");
    }
    let (e, mut h, c) = harness_with(|e| e.set_property("target-transition", 0u64));
    let mut out = Vec::new();
    for (i, nick) in ["warm-key-left", "cool-key-right", "candle", "soft-front"]
        .iter()
        .enumerate()
    {
        e.set_property_from_str("target-preset", nick);
        out.push(relight(&mut h, &c, i as u64));
    }
    // A light's colour shows: a warm key warms the face, a cool one cools it
    // (its side is held on real faces by `tests/real_footage.rs`).
    assert!(
        warmth(&out[0]) > warmth(&out[1]) + 3.0,
        "warm key left {:.1}, cool key right {:.1}",
        warmth(&out[0]),
        warmth(&out[1])
    );
    assert!(
        mean(&out[2]) + 10.0 < mean(&out[3]),
        "a candle-lit face is darker than a softly front-lit one ({:.1} vs {:.1})",
        mean(&out[2]),
        mean(&out[3])
    );
    // The preset overrides target-location; none gives it back.
    e.set_property_from_str("target-preset", "none");
    e.set_property("target-location", target("studio"));
    let studio = relight(&mut h, &c, 4);
    let (_, mut h2, _) = harness_with(|e| e.set_property("target-location", target("studio")));
    assert!(mean_abs_diff(&studio, &relight(&mut h2, &c, 0)) < 0.5);
}

#[test]
fn a_target_change_fades_over_the_transition_instead_of_jumping() {
    let transition = gst::ClockTime::from_mseconds(400);
    let (e, mut h, c) = harness_with(|e| {
        e.set_property("target-transition", transition.nseconds());
        e.set_property_from_str("target-preset", "soft-front");
    });
    let before = relight(&mut h, &c, 0);
    e.set_property_from_str("target-preset", "candle");
    let mut frames = vec![before.clone()];
    for i in 1..=20 {
        frames.push(relight(&mut h, &c, i));
    }
    // The whole change, as a fresh element relighting to the new target shows it.
    let (_, mut fresh, _) = harness_with(|e| e.set_property_from_str("target-preset", "candle"));
    let after = relight(&mut fresh, &c, 0);
    let whole = mean(&before) - mean(&after);
    assert!(
        whole > 10.0,
        "the change is large enough to see: {whole:.1}"
    );
    // 400 ms at 30 fps: 12 frames. Each step may move at most a few twelfths of it
    // (the network is not linear in the light); none moves it all at once.
    let steps = transition.nseconds() as f64 / FRAME.nseconds() as f64;
    let largest = frames
        .windows(2)
        .map(|w| (mean(&w[0]) - mean(&w[1])).abs())
        .fold(0.0, f64::max);
    assert!(
        largest < 3.0 * whole / steps,
        "largest step {largest:.2} of {whole:.1} levels over {steps:.0} frames"
    );
    // Half way it is part way; after the transition it is the new target.
    let half = mean(&frames[7]);
    assert!(half < mean(&before) - 0.15 * whole && half > mean(&after) + 0.15 * whole);
    let end = &frames[20];
    assert!(mean_abs_diff(end, &after) < 0.5, "reaches the new target");
    // One encode per faded frame, then none.
    let encodes = stat(&e, "target-encodes");
    assert!((12..=15).contains(&encodes), "{encodes}");
    relight(&mut h, &c, 21);
    assert_eq!(stat(&e, "target-encodes"), encodes);
}

/// A small EXR panorama: dim grey, with a bright warm band 20 degrees wide
/// around `lon` degrees (negative: the viewer's left), written with the `image` crate.
fn write_panorama(path: &std::path::Path, lon: f64) {
    let (w, h) = (180u32, 90u32);
    let img = image::Rgb32FImage::from_fn(w, h, |x, y| {
        let at = (x as f64 + 0.5) / w as f64 * 360.0 - 180.0;
        let lat = 90.0 - (y as f64 + 0.5) / h as f64 * 180.0;
        if (at - lon).abs() < 10.0 && lat.abs() < 40.0 {
            image::Rgb([6.0, 3.0, 1.0])
        } else {
            image::Rgb([0.05, 0.05, 0.05])
        }
    });
    img.save_with_format(path, image::ImageFormat::OpenExr)
        .unwrap();
}

fn temp_path(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("lsyd-targets-{}-{name}", std::process::id()))
}

#[test]
fn an_environment_map_view_follows_a_controller_while_playing() {
    let map = temp_path("left.exr");
    write_panorama(&map, -60.0);
    let map_str = map.to_str().unwrap().to_owned();
    let (e, mut h, c) = harness_with(|e| {
        e.set_property("target-transition", 0u64);
        e.set_property("target-environment", &map_str);
    });
    let start = relight(&mut h, &c, 0);
    // Turn the viewer 90 degrees right over 10 frames: the warm band on the
    // user's left leaves the screen.
    let source = gst_controller::InterpolationControlSource::new();
    source.set_mode(gst_controller::InterpolationMode::Linear);
    source.set(frame_time(1), 0.0);
    source.set(frame_time(11), 90.0);
    let binding = gst_controller::DirectControlBinding::new_absolute(&e, "target-yaw", &source);
    e.add_control_binding(&binding).unwrap();
    let encodes = stat(&e, "target-encodes");
    let mut last = start.clone();
    for i in 1..=12 {
        last = relight(&mut h, &c, i);
    }
    assert!((e.property::<f64>("target-yaw") - 90.0).abs() < 1e-6);
    // 9 degrees a frame: yaws 9, 18, 27 and 36 show the band, 45 and beyond do
    // not (it spans 70 to 50 degrees left). A code is computed only when the light changes.
    assert_eq!(stat(&e, "target-encodes"), encodes + 5);
    // The same as an element set to that view from the start.
    let (_, mut fixed, _) = harness_with(|e| {
        e.set_property("target-environment", &map_str);
        e.set_property("target-yaw", 90.0f64);
    });
    let want = relight(&mut fixed, &c, 0);
    assert!(mean_abs_diff(&last, &want) < 0.5);
    assert!(
        mean(&start) > mean(&last) + 5.0,
        "the bright light left the screen: {:.1} -> {:.1}",
        mean(&start),
        mean(&last)
    );

    // A map that cannot be read keeps the previous target, with a warning.
    let bus = gst::Bus::new();
    e.set_bus(Some(&bus));
    e.set_property("target-environment", "/nonexistent/room.hdr");
    let warning = bus
        .pop_filtered(&[gst::MessageType::Warning])
        .expect("a warning");
    let gst::MessageView::Warning(w) = warning.view() else {
        unreachable!()
    };
    assert!(
        w.error().to_string().contains("/nonexistent/room.hdr"),
        "{}",
        w.error()
    );
    std::fs::remove_file(&map).ok();
}

#[test]
fn an_unreadable_environment_map_is_an_error_at_start_naming_it() {
    let e = element();
    e.set_property("target-environment", "/nonexistent/room.exr");
    let pipeline = gst::Pipeline::new();
    let src = gst::ElementFactory::make("videotestsrc")
        .property("num-buffers", 1)
        .build()
        .unwrap();
    let sink = gst::ElementFactory::make("fakesink").build().unwrap();
    pipeline.add_many([&src, &e, &sink]).unwrap();
    gst::Element::link_many([&src, &e, &sink]).unwrap();
    let _ = pipeline.set_state(gst::State::Playing);
    let msg = pipeline
        .bus()
        .unwrap()
        .timed_pop_filtered(gst::ClockTime::from_seconds(10), &[gst::MessageType::Error])
        .expect("an error");
    let gst::MessageView::Error(err) = msg.view() else {
        unreachable!()
    };
    let text = format!("{} {:?}", err.error(), err.debug());
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(
        text.contains("/nonexistent/room.exr") && text.contains("target-environment"),
        "{text}"
    );
}

#[test]
fn a_video_target_lights_the_face_frame_by_frame_and_keeps_its_last_frame() {
    use deskstage::math::Vec3;
    use lsydrelight_testkit::video::monitor_buffer;
    let e = element();
    e.set_property("alpha", 1.0f32);
    // Each background frame stays the target for its duration or 0.2 s, whichever is longer.
    e.set_property("monitor-timeout", 200_000_000u64);
    let bus = gst::Bus::new();
    e.set_bus(Some(&bus));
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let mut th = Harness::with_element(&e, Some("target_sink"), None);
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    th.set_src_caps(lsydrelight_testkit::video::rgb_caps(256, 144, 10));
    // A 10 fps background: white for half a second, then dark blue; then it ends.
    let pusher = std::thread::spawn(move || {
        let d = gst::ClockTime::from_mseconds(100);
        for k in 0..10u64 {
            let colour = if k < 5 {
                Vec3::new(1.0, 1.0, 1.0)
            } else {
                Vec3::new(0.05, 0.05, 0.4)
            };
            if th.push(monitor_buffer(colour, d * k, d)).is_err() {
                break;
            }
        }
        th.push_event(gst::event::Eos::new());
        th
    });
    let mut out = Vec::new();
    for i in 0..45 {
        h.push(buffer(face_rgb(), &c, frame_time(i), FRAME))
            .unwrap();
        out.push(to_rgb(&h.pull().unwrap(), &c));
    }
    pusher.join().unwrap();
    // One light per target frame, computed on the target stream's thread as it
    // arrived, and a code only when the light changes: the start's target, white, blue.
    let (arrived, on_arrival, decoded) = (
        stat(&e, "target-stream-frames"),
        stat(&e, "target-stream-arrival-decoded"),
        stat(&e, "target-stream-decoded"),
    );
    assert!(
        (9..=10).contains(&arrived) && on_arrival == arrived && decoded == 0,
        "{arrived} frames, {on_arrival} lights on arrival, {decoded} when used"
    );
    assert_eq!(stat(&e, "target-encodes"), 3);
    let (white, blue, after) = (mean(&out[10]), mean(&out[25]), mean(&out[40]));
    assert!(white > blue + 10.0, "white {white:.1}, blue {blue:.1}");
    assert!(
        (after - blue).abs() < 0.5,
        "the ended stream's last frame stays the target"
    );
    let warnings: Vec<String> =
        std::iter::from_fn(|| bus.pop_filtered(&[gst::MessageType::Warning]))
            .map(|m| match m.view() {
                gst::MessageView::Warning(w) => w.error().to_string(),
                _ => unreachable!(),
            })
            .collect();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(
        warnings[0].contains("Keeping the last target light"),
        "{warnings:?}"
    );
}
