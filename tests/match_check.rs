//! The monitor-match check through the element: with `match-check` on and a
//! monitor stream, a message about once a second says whether the light on the
//! face follows the screen. A face lit by the screen passes; the same face with
//! another screen's stream fails. And the light decoder, whose prediction shows a
//! blurred view of the user's screen, runs only when someone asked for it.

use std::sync::OnceLock;

use deskstage::material::Look;
use deskstage::math::Vec3;
use deskstage::monitor::{CellLight, RgbImage};
use deskstage::render::{Renderer, Scene, Sensor};
use deskstage::subject::{State, Subject};
use gst::prelude::*;
use lsydrelight_testkit::element::stat;
use lsydrelight_testkit::person::{FACE_H, FACE_W};
use lsydrelight_testkit::video::{buffer, monitor_buffer, rgb_caps};
use lsydrelight_testkit::{init, target};

const FPS: u64 = 15;
const FRAMES: u64 = 6 * FPS;

/// What the screen shows, cut to cut: bright and dark, warm and cool.
const SCREENS: [[f32; 3]; 6] = [
    [0.08, 0.08, 0.08],
    [1.0, 1.0, 1.0],
    [0.45, 0.35, 0.25],
    [0.75, 0.85, 1.0],
    [0.2, 0.25, 0.35],
    [0.6, 0.6, 0.55],
];

/// The person, frontal, lit by each screen (rendered once).
fn faces() -> &'static [RgbImage] {
    static FACES: OnceLock<Vec<RgbImage>> = OnceLock::new();
    FACES.get_or_init(|| {
        let r = Renderer::new(Scene::new(
            Subject::default(),
            FACE_W as usize,
            FACE_H as usize,
        ))
        .unwrap();
        let transport = r.prepare(&Look::default(), &State::default());
        let lights: Vec<CellLight> = SCREENS
            .iter()
            .map(|&[r, g, b]| CellLight::uniform(16, 32, Vec3::new(r, g, b)))
            .collect();
        let lights: Vec<&CellLight> = lights.iter().collect();
        r.render(&transport, &lights)
            .iter()
            .map(|img| Sensor::default().clean(img))
            .collect()
    })
}

/// Which screen each frame shows: content cut every 0.4 to 1 s, in an order
/// and at times that differ between `seed`s, as two recordings' would.
fn playlist(seed: usize) -> Vec<usize> {
    let lengths = [8, 12, 6, 14, 9, 11, 7, 13, 10, 15];
    let mut out = Vec::new();
    let mut segment = 0;
    while (out.len() as u64) < FRAMES {
        let screen = (segment * (seed + 1) + seed * 2) % SCREENS.len();
        let length = lengths[(segment + 3 * seed) % lengths.len()];
        out.extend(std::iter::repeat_n(screen, length));
        segment += 1;
    }
    out.truncate(FRAMES as usize);
    out
}

fn time(i: u64) -> gst::ClockTime {
    gst::ClockTime::from_nseconds(i * 1_000_000_000 / FPS)
}

/// What a run of the element reported.
struct Run {
    messages: Vec<gst::Structure>,
    predictions: u64,
    frames: u64,
}

/// Plays the face lit by `lit_by`'s screens with `shown`'s monitor stream through
/// the element, `properties` set, and collects its monitor-match messages.
fn run(lit_by: &[usize], shown: &[usize], properties: &[(&str, &str)]) -> Run {
    init();
    let pipeline = gst::parse::launch(
        "appsrc name=face format=time ! lsydrelight name=r ! fakesink sync=false \
         appsrc name=monitor format=time ! r.monitor_sink",
    )
    .unwrap()
    .downcast::<gst::Pipeline>()
    .unwrap();
    let r = pipeline.by_name("r").unwrap();
    r.set_property("target-location", target("studio"));
    for (k, v) in properties {
        r.set_property_from_str(k, v);
    }
    let appsrc = |name| {
        let src = pipeline
            .by_name(name)
            .unwrap()
            .downcast::<gst_app::AppSrc>()
            .unwrap();
        // Every frame is queued before the pipeline plays.
        src.set_max_bytes(u64::MAX);
        src
    };
    let (face, monitor) = (appsrc("face"), appsrc("monitor"));
    let face_caps = rgb_caps(FACE_W, FACE_H, FPS as i32);
    face.set_caps(Some(&face_caps));
    let duration = time(1);
    for i in 0..FRAMES {
        let img = &faces()[lit_by[i as usize]];
        face.push_buffer(buffer(img, &face_caps, time(i), duration))
            .unwrap();
        let [red, green, blue] = SCREENS[shown[i as usize]];
        let screen = monitor_buffer(Vec3::new(red, green, blue), time(i), duration);
        if i == 0 {
            let caps = screen_caps();
            monitor.set_caps(Some(&caps));
        }
        monitor.push_buffer(screen).unwrap();
    }
    face.end_of_stream().unwrap();
    monitor.end_of_stream().unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let bus = pipeline.bus().unwrap();
    let mut messages = Vec::new();
    for msg in bus.iter_timed(gst::ClockTime::from_seconds(60)) {
        match msg.view() {
            gst::MessageView::Eos(_) => break,
            gst::MessageView::Error(e) => panic!("{} ({:?})", e.error(), e.debug()),
            gst::MessageView::Element(e) => {
                if let Some(s) = e.structure()
                    && s.name() == "lsydrelight-monitor-match"
                {
                    messages.push(s.to_owned());
                }
            }
            _ => {}
        }
    }
    pipeline.set_state(gst::State::Null).unwrap();
    Run {
        messages,
        predictions: stat(&r, "light-predictions"),
        frames: stat(&r, "frames"),
    }
}

/// The caps of the monitor frames `monitor_buffer` makes.
fn screen_caps() -> gst::Caps {
    let img = lsydrelight_testkit::person::monitor_rgb(Vec3::new(1.0, 1.0, 1.0));
    rgb_caps(img.width as u32, img.height as u32, FPS as i32)
}

fn verdict(s: &gst::Structure) -> String {
    s.get::<String>("verdict").unwrap()
}

#[test]
fn a_face_lit_by_the_screen_passes_and_another_screen_fails() {
    let check = [("match-check", "true"), ("match-window", "3")];
    let genuine = run(&playlist(0), &playlist(0), &check);
    assert_eq!(genuine.frames, FRAMES);
    // About once a second of stream time: at 1, 2, ... 5 s of a 6 s stream.
    let times: Vec<u64> = genuine
        .messages
        .iter()
        .map(|s| s.get::<gst::ClockTime>("running-time").unwrap().mseconds())
        .collect();
    assert!(
        (4..=6).contains(&times.len()),
        "messages at {times:?} ms for a 6 s stream"
    );
    for pair in times.windows(2) {
        let gap = pair[1] - pair[0];
        assert!((900..=1100).contains(&gap), "messages at {times:?} ms");
    }
    for s in &genuine.messages {
        assert_eq!(s.get::<f64>("window").unwrap(), 3.0);
        assert!(s.get::<u32>("frames").unwrap() > 0, "{s}");
    }
    // Once the window holds 3 s of frames, the verdict is given, and it passes.
    let full = &genuine.messages[genuine.messages.len() - 2..];
    for s in full {
        assert_eq!(s.get::<u32>("frames").unwrap(), 3 * FPS as u32, "{s}");
        assert_eq!(verdict(s), "match", "the face is lit by this screen: {s}");
        assert!(s.get::<f64>("luminance").is_ok(), "{s}");
    }

    let swapped = run(&playlist(0), &playlist(1), &check);
    let last = swapped
        .messages
        .last()
        .expect("messages with another screen");
    assert_eq!(
        verdict(last),
        "mismatch",
        "the face is lit by another screen than the one shown: {last}"
    );
    let (g, w) = (
        full[1].get::<f64>("score").unwrap(),
        last.get::<f64>("score").unwrap(),
    );
    assert!(g > w, "genuine score {g}, swapped {w}");
}

#[test]
fn the_light_decoder_runs_only_when_asked() {
    let screens = playlist(0);
    // A monitor stream, monitor_src unlinked, the check off: the source light is
    // known and nobody looks at a prediction.
    let off = run(&screens, &screens, &[]);
    assert_eq!(off.frames, FRAMES);
    assert_eq!(
        off.predictions, 0,
        "the light decoder ran with nobody asking"
    );
    assert!(off.messages.is_empty(), "no check, no messages");
    let on = run(&screens, &screens, &[("match-check", "true")]);
    assert!(on.predictions > 0, "the check needs the prediction");
}
