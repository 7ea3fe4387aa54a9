//! The element's pads, caps and negotiation for every format, unknown-source
//! mode, the predicted-monitor output, target changes and state resets.

use deskstage::math::Vec3;
use deskstage::subject::{Pose, State};
use gst::prelude::*;
use gst_check::Harness;
use gstlsydrelight::targets::Preset;
use lsydrelight_testkit::{
    element::{element, monitor_time, stat},
    init,
    person::{FACE_H, FACE_W, face_rgb, render_face, render_person},
    target,
    video::{
        FORMATS, FRAME, buffer, caps, frame_time, mean_abs_diff, monitor_buffer, rgb_caps, to_rgb,
    },
};

/// A harness on the face pad only: unknown-source mode.
fn face_harness(format: gst_video::VideoFormat) -> (gst::Element, Harness) {
    let e = element();
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    h.set_src_caps(caps(format, FACE_W, FACE_H, 30));
    (e, h)
}

#[test]
fn pads_templates_and_documentation() {
    let e = element();
    assert!(e.static_pad("sink").is_some());
    assert!(e.static_pad("src").is_some());
    assert!(e.static_pad("monitor_src").is_some());
    assert!(
        e.static_pad("monitor_sink").is_none(),
        "monitor_sink is requested, not always there"
    );
    let monitor = e
        .request_pad_simple("monitor_sink")
        .expect("monitor_sink can be requested");
    assert_eq!(monitor.name(), "monitor_sink");
    assert!(
        e.request_pad_simple("monitor_sink").is_none(),
        "there is one monitor stream"
    );
    e.release_request_pad(&monitor);
    assert!(
        e.request_pad_simple("monitor_sink").is_some(),
        "a released monitor pad can be requested again"
    );

    let factory = e.factory().unwrap();
    assert_eq!(factory.metadata("klass"), Some("Filter/Effect/Video"));
    for p in e.list_properties() {
        if p.owner_type() == e.type_() {
            assert!(
                p.blurb().is_some_and(|b| b.len() > 20),
                "property {} needs a blurb",
                p.name()
            );
        }
    }
}

#[test]
fn negotiates_and_relights_every_format() {
    let face = face_rgb();
    for format in FORMATS {
        let (e, mut h) = face_harness(format);
        e.set_property("target-location", target("left-key"));
        let c = caps(format, FACE_W, FACE_H, 30);
        let input = buffer(face, &c, frame_time(3), FRAME);
        h.push(input.clone()).unwrap();
        let out = h.pull().unwrap();
        let out_caps = h.sinkpad().unwrap().current_caps().unwrap();
        assert_eq!(out_caps, c, "{format:?}: output caps must equal input caps");
        assert_eq!(
            out.pts(),
            Some(frame_time(3)),
            "{format:?}: timestamps pass through"
        );
        assert_eq!(out.duration(), Some(FRAME));
        let before = to_rgb(&input, &c);
        let after = to_rgb(&out, &c);
        let changed = mean_abs_diff(&before, &after);
        assert!(
            changed > 2.0,
            "{format:?}: relighting to a side light must change the frame (mean change {changed:.2})"
        );
        assert_eq!(stat(&e, "relit"), 1);
    }
}

#[test]
fn refuses_unsupported_caps() {
    let e = element();
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    h.set_src_caps(caps(gst_video::VideoFormat::Gray8, FACE_W, FACE_H, 30));
    let info = gst_video::VideoInfo::builder(gst_video::VideoFormat::Gray8, FACE_W, FACE_H)
        .build()
        .unwrap();
    let r = h.push(gst::Buffer::with_size(info.size()).unwrap());
    assert_eq!(r, Err(gst::FlowError::NotNegotiated));
}

/// What a pipeline reports when a source sends caps the element cannot take.
fn caps_error(format: gst_video::VideoFormat, width: u32, height: u32) -> String {
    init();
    let pipeline = gst::Pipeline::new();
    let src = gst_app::AppSrc::builder()
        .caps(&caps(format, width, height, 30))
        .format(gst::Format::Time)
        .build();
    let relight = element();
    let sink = gst::ElementFactory::make("fakesink").build().unwrap();
    pipeline
        .add_many([src.upcast_ref(), &relight, &sink])
        .unwrap();
    gst::Element::link_many([src.upcast_ref(), &relight, &sink]).unwrap();
    pipeline.set_state(gst::State::Playing).unwrap();
    let info = gst_video::VideoInfo::builder(format, width, height)
        .build()
        .unwrap();
    let _ = src.push_buffer(gst::Buffer::with_size(info.size()).unwrap());
    let _ = src.end_of_stream();
    let bus = pipeline.bus().unwrap();
    let mut texts = Vec::new();
    while let Some(msg) = bus.timed_pop_filtered(
        gst::ClockTime::from_seconds(30),
        &[gst::MessageType::Error, gst::MessageType::Eos],
    ) {
        if let gst::MessageView::Error(e) = msg.view() {
            texts.push(format!("{} {:?}", e.error(), e.debug()));
        }
        if texts.len() > 1 || matches!(msg.view(), gst::MessageView::Eos(_)) {
            break;
        }
    }
    pipeline.set_state(gst::State::Null).unwrap();
    texts.join("\n")
}

#[test]
fn unsupported_caps_name_the_problem_and_the_fix() {
    let gray = caps_error(gst_video::VideoFormat::Gray8, FACE_W, FACE_H);
    assert!(
        gray.contains("GRAY8") && gray.contains("videoconvert") && gray.contains("I420"),
        "{gray}"
    );
    let tiny = caps_error(gst_video::VideoFormat::I420, 8, 8);
    assert!(tiny.contains("at least 16x16"), "{tiny}");
}

#[test]
fn the_default_model_is_the_starter_model_for_anyone() {
    init();
    let e = gst::ElementFactory::make("lsydrelight").build().unwrap();
    let model: String = e.property("model-location");
    assert!(
        model.ends_with("models/starter"),
        "until the user trains their own, the element relights with the starter model: {model}"
    );
    // It loads and relights the tests' person, whom it never saw, with no monitor stream.
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    h.push(buffer(face_rgb(), &c, frame_time(0), FRAME))
        .unwrap();
    let out = h.pull().unwrap();
    let relit = to_rgb(&out, &c);
    assert!(
        mean_abs_diff(&relit, face_rgb()) > 1.0,
        "the starter model relights the face"
    );
    assert_eq!(stat(&e, "passed-through"), 0);
}

#[test]
fn relights_without_a_monitor_stream() {
    let (e, mut h) = face_harness(gst_video::VideoFormat::Rgb);
    // The same frame three times would be a static scene; run the network every time.
    e.set_property("reuse-interval", 1u32);
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    for i in 0..3 {
        h.push(buffer(face_rgb(), &c, frame_time(i), FRAME))
            .unwrap();
        let out = h.pull().unwrap();
        assert!(
            monitor_time(&out).is_none(),
            "no monitor frame lit this one"
        );
    }
    assert_eq!(stat(&e, "predicted-source"), 3);
    assert_eq!(stat(&e, "known-source"), 0);
    assert_eq!(
        stat(&e, "light-predictions"),
        3,
        "unknown-source mode always predicts"
    );
}

/// `source-preset` states the light the face is lit by when no monitor stream is
/// connected: it stands in for the monitor's light (nothing is predicted), the
/// relighting differs from the predicted light's, and a target equal to it
/// passes the face unchanged.
#[test]
fn a_stated_source_light_stands_in_for_a_missing_monitor_stream() {
    let relit_from = |source: Preset, target: Preset| {
        let (e, mut h) = face_harness(gst_video::VideoFormat::Rgb);
        e.set_property("reuse-interval", 1u32);
        e.set_property("target-transition", 0u64);
        e.set_property("source-preset", source);
        e.set_property("target-preset", target);
        let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
        let mut out = None;
        for i in 0..3 {
            h.push(buffer(face_rgb(), &c, frame_time(i), FRAME))
                .unwrap();
            out = Some(to_rgb(&h.pull().unwrap(), &c));
        }
        (e, out.unwrap())
    };
    // The tests' person is lit by a white screen, which the network predicts;
    // neon is far from it.
    let (e, stated) = relit_from(Preset::Neon, Preset::WarmKeyLeft);
    assert_eq!(stat(&e, "assumed-source"), 3);
    assert_eq!(stat(&e, "known-source"), 3);
    assert_eq!(stat(&e, "predicted-source"), 0);
    assert_eq!(stat(&e, "light-predictions"), 0, "nothing to predict");
    let (_, predicted) = relit_from(Preset::None, Preset::WarmKeyLeft);
    assert!(
        mean_abs_diff(&stated, &predicted) > 1.0,
        "the stated light is the one relit from"
    );
    let (e, same) = relit_from(Preset::SoftFront, Preset::SoftFront);
    assert_eq!(&same, face_rgb(), "relit to the light it is lit by");
    assert_eq!(stat(&e, "skipped-same-light"), 3);
}

#[test]
fn predicted_monitor_is_a_small_video_at_the_face_rate() {
    let e = element();
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let mut side = Harness::with_element(&e, None, Some("monitor_src"));
    h.set_src_caps(caps(gst_video::VideoFormat::I420, FACE_W, FACE_H, 25));
    let c = caps(gst_video::VideoFormat::I420, FACE_W, FACE_H, 25);
    h.push(buffer(
        &render_face(Vec3::new(1.0, 1.0, 1.0)),
        &c,
        gst::ClockTime::ZERO,
        FRAME,
    ))
    .unwrap();
    h.pull().unwrap();
    let predicted = side.pull().unwrap();
    let pc = side.sinkpad().unwrap().current_caps().unwrap();
    let s = pc.structure(0).unwrap();
    assert_eq!(s.get::<&str>("format").unwrap(), "RGB");
    assert_eq!(
        (
            s.get::<i32>("width").unwrap(),
            s.get::<i32>("height").unwrap()
        ),
        (256, 128)
    );
    assert_eq!(
        s.get::<gst::Fraction>("framerate").unwrap(),
        gst::Fraction::new(25, 1)
    );
    assert_eq!(predicted.pts(), Some(gst::ClockTime::ZERO));
    // A white monitor lit the face: the predicted screen is bright and neutral.
    let mean = channel_means(&predicted.map_readable().unwrap());
    assert!(
        mean.iter().all(|&m| m > 90.0),
        "predicted white monitor too dark: {mean:?}"
    );
    assert!(
        (mean[0] - mean[2]).abs() < 60.0,
        "predicted white monitor not neutral: {mean:?}"
    );

    // A dark blue monitor: the prediction follows it down, and towards blue (the
    // default model's refitted light decoder follows the screen's colour; see the
    // model card).
    h.push(buffer(
        &render_face(Vec3::new(0.05, 0.05, 0.6)),
        &c,
        FRAME,
        FRAME,
    ))
    .unwrap();
    h.pull().unwrap();
    let dark = side.pull().unwrap();
    let dark = channel_means(&dark.map_readable().unwrap());
    let dark_mean = dark.iter().sum::<f64>() / 3.0;
    let white_mean = mean.iter().sum::<f64>() / 3.0;
    assert!(
        dark_mean < 0.5 * white_mean,
        "a dark monitor must be predicted darker than a white one ({dark_mean} vs {white_mean})"
    );
    let blue_share = |rgb: [f64; 3]| rgb[2] / rgb.iter().sum::<f64>();
    assert!(
        blue_share(dark) > blue_share(mean) + 0.2,
        "a blue monitor must be predicted bluer than a white one ({dark:?} vs {mean:?})"
    );
}

/// Mean of each channel of packed 8-bit RGB pixels.
fn channel_means(rgb: &[u8]) -> [f64; 3] {
    let pixels = (rgb.len() / 3) as f64;
    std::array::from_fn(|c| {
        rgb.iter()
            .skip(c)
            .step_by(3)
            .map(|&v| v as f64)
            .sum::<f64>()
            / pixels
    })
}

#[test]
fn prediction_runs_only_when_someone_needs_it() {
    let e = element();
    let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
    let mut mh = Harness::with_element(&e, Some("monitor_sink"), None);
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    h.set_src_caps(c.clone());
    mh.set_src_caps(rgb_caps(256, 144, 30));
    // Each face frame goes in before the monitor frame after it: a sink pad holds one
    // buffer until the element takes it, and it takes monitor frames for face frames.
    let grey = |i| monitor_buffer(Vec3::new(0.8, 0.8, 0.8), frame_time(i), FRAME);
    mh.push(grey(0)).unwrap();
    for i in 1..3 {
        h.push(buffer(face_rgb(), &c, frame_time(i - 1), FRAME))
            .unwrap();
        mh.push(grey(i)).unwrap();
        h.pull().unwrap();
    }
    assert_eq!(stat(&e, "known-source"), 2);
    assert_eq!(
        stat(&e, "light-predictions"),
        0,
        "monitor_src is unlinked and the source is known"
    );
}

/// A monitor frame of one colour (8-bit sRGB) in `caps`, stamped at frame `i`.
fn monitor_frame(rgb: [u8; 3], caps: &gst::Caps, i: u64) -> gst::Buffer {
    let info = gst_video::VideoInfo::from_caps(caps).unwrap();
    let mut img = deskstage::monitor::RgbImage::new(info.width() as usize, info.height() as usize);
    img.data
        .chunks_mut(3)
        .for_each(|px| px.copy_from_slice(&rgb));
    buffer(&img, caps, frame_time(i), FRAME)
}

#[test]
fn a_monitor_stream_that_changes_format_and_size_is_read_in_its_new_caps() {
    // A screen capture renegotiates mid-call (a window resized, another
    // format): the frames after the caps event are read in the new caps, and
    // relight the face as a stream in those caps from the start does.
    init();
    const RED: [u8; 3] = [230, 40, 30];
    const BLUE: [u8; 3] = [30, 60, 230];
    let rgb = rgb_caps(256, 144, 30);
    let bgrx = caps(gst_video::VideoFormat::Bgrx, 64, 36, 30);
    // The light of each frame alone, nothing carried between frames: the
    // outputs compare frame by frame.
    let run = |monitor: &dyn Fn(u64) -> ([u8; 3], gst::Caps)| {
        let e = element();
        e.set_property("alpha", 1.0f32);
        e.set_property("average-frames", 1u32);
        e.set_property("reuse-interval", 1u32);
        e.set_property("denoise", false);
        let mut h = Harness::with_element(&e, Some("sink"), Some("src"));
        let mut mh = Harness::with_element(&e, Some("monitor_sink"), None);
        let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
        h.set_src_caps(c.clone());
        let mut shown = None;
        let mut outs = Vec::new();
        // A face frame goes in before the monitor frame after it (see
        // `prediction_runs_only_when_someone_needs_it`).
        for i in 0..7 {
            let (colour, caps) = monitor(i);
            if shown.as_ref() != Some(&caps) {
                mh.set_src_caps(caps.clone());
                shown = Some(caps.clone());
            }
            if i > 0 {
                h.push(buffer(face_rgb(), &c, frame_time(i - 1), FRAME))
                    .unwrap();
            }
            mh.push(monitor_frame(colour, &caps, i)).unwrap();
            if i > 0 {
                outs.push(to_rgb(&h.pull().unwrap(), &c));
            }
        }
        assert_eq!(
            stat(&e, "known-source"),
            6,
            "every frame had its monitor light"
        );
        assert_eq!(stat(&e, "relit"), 6);
        outs
    };
    let changing = run(&|i| {
        if i < 3 {
            (RED, rgb.clone())
        } else {
            (BLUE, bgrx.clone())
        }
    });
    let blue_from_the_start = run(&|_| (BLUE, bgrx.clone()));
    let red_throughout = run(&|_| (RED, rgb.clone()));
    for i in 0..3 {
        assert!(
            mean_abs_diff(&changing[i], &red_throughout[i]) < 0.01,
            "frame {i}: before the change, the red screen's light"
        );
    }
    for i in 3..6 {
        assert!(
            mean_abs_diff(&changing[i], &blue_from_the_start[i]) < 0.01,
            "frame {i}: after the change, the blue BGRx screen's light"
        );
        assert!(
            mean_abs_diff(&changing[i], &red_throughout[i]) > 1.0,
            "frame {i}: the source light shows in the output"
        );
    }
}

#[test]
fn target_can_change_while_playing() {
    let (e, mut h) = face_harness(gst_video::VideoFormat::Rgb);
    e.set_property("alpha", 1.0f32);
    // Without a crossfade (tests/targets.rs has those) the next frame has the new target.
    e.set_property("target-transition", 0u64);
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    e.set_property("target-location", target("studio"));
    h.push(buffer(face_rgb(), &c, frame_time(0), FRAME))
        .unwrap();
    let studio = to_rgb(&h.pull().unwrap(), &c);
    e.set_property("target-location", target("sunset"));
    h.push(buffer(face_rgb(), &c, frame_time(1), FRAME))
        .unwrap();
    let sunset = to_rgb(&h.pull().unwrap(), &c);
    assert!(
        mean_abs_diff(&studio, &sunset) > 1.0,
        "the next frame uses the new target"
    );

    // The same frame relit by a fresh element set to the sunset target from the start.
    let (e2, mut h2) = face_harness(gst_video::VideoFormat::Rgb);
    e2.set_property("alpha", 1.0f32);
    e2.set_property("target-location", target("sunset"));
    h2.push(buffer(face_rgb(), &c, frame_time(0), FRAME))
        .unwrap();
    let fresh = to_rgb(&h2.pull().unwrap(), &c);
    let d = mean_abs_diff(&sunset, &fresh);
    assert!(
        d < 0.5,
        "changing the target mid-stream gives what a fresh stream gives (diff {d:.3})"
    );
    assert_eq!(stat(&e, "target-encodes"), 2, "each target is encoded once");

    // A target that cannot be read keeps the previous one, with a warning.
    e.set_property("target-location", "/nonexistent/target.png");
    h.push(buffer(face_rgb(), &c, frame_time(2), FRAME))
        .unwrap();
    let kept = to_rgb(&h.pull().unwrap(), &c);
    assert!(mean_abs_diff(&kept, &sunset) < 0.5);
}

#[test]
fn state_resets_on_flush_discontinuity_caps_and_gaps() {
    let (e, mut h) = face_harness(gst_video::VideoFormat::Rgb);
    let c = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 30);
    let bright = render_face(Vec3::new(1.0, 1.0, 1.0));
    let dim = render_face(Vec3::new(0.3, 0.2, 0.2));
    let run = |h: &mut Harness, img: &deskstage::monitor::RgbImage, i: u64, discont: bool| {
        let mut b = buffer(img, &c, frame_time(i), FRAME);
        if discont {
            b.get_mut().unwrap().set_flags(gst::BufferFlags::DISCONT);
        }
        h.push(b).unwrap();
        to_rgb(&h.pull().unwrap(), &c)
    };
    let first_dim = {
        let (_, mut fresh) = face_harness(gst_video::VideoFormat::Rgb);
        run(&mut fresh, &dim, 0, false)
    };
    // With history, the dim frame is smoothed with the bright one.
    run(&mut h, &bright, 0, false);
    let smoothed = run(&mut h, &dim, 1, false);
    assert!(
        mean_abs_diff(&smoothed, &first_dim) > 0.3,
        "smoothing carries state between frames"
    );
    let resets = stat(&e, "resets");

    // A discontinuity starts afresh: the result equals a first frame's.
    run(&mut h, &bright, 2, false);
    let after_discont = run(&mut h, &dim, 3, true);
    assert!(mean_abs_diff(&after_discont, &first_dim) < 0.05);
    assert!(stat(&e, "resets") > resets);

    // A gap longer than reset-gap starts afresh too.
    run(&mut h, &bright, 4, false);
    let after_gap = run(&mut h, &dim, 4 + 60, false);
    assert!(mean_abs_diff(&after_gap, &first_dim) < 0.05);

    // So does a flush.
    run(&mut h, &bright, 70, false);
    assert!(h.push_event(gst::event::FlushStart::new()));
    assert!(h.push_event(gst::event::FlushStop::new(true)));
    assert!(
        h.push_event(gst::event::Segment::new(&gst::FormattedSegment::<
            gst::ClockTime,
        >::new()))
    );
    let after_flush = run(&mut h, &dim, 71, false);
    assert!(mean_abs_diff(&after_flush, &first_dim) < 0.05);

    // And a caps change.
    run(&mut h, &bright, 72, false);
    let before = stat(&e, "resets");
    let c2 = caps(gst_video::VideoFormat::Rgb, FACE_W, FACE_H, 15);
    h.set_src_caps(c2.clone());
    h.push(buffer(&dim, &c2, frame_time(73), FRAME)).unwrap();
    let after_caps = to_rgb(&h.pull().unwrap(), &c2);
    assert!(stat(&e, "resets") > before);
    assert!(mean_abs_diff(&after_caps, &first_dim) < 0.05);
}

/// Counts the buffers and GAP events that reach `pad`.
fn count_frames(pad: &gst::Pad) -> std::sync::Arc<std::sync::atomic::AtomicUsize> {
    let count = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let seen = count.clone();
    pad.add_probe(
        gst::PadProbeType::BUFFER | gst::PadProbeType::EVENT_DOWNSTREAM,
        move |_, info| {
            let frame = match &info.data {
                Some(gst::PadProbeData::Buffer(_)) => true,
                Some(gst::PadProbeData::Event(e)) => e.type_() == gst::EventType::Gap,
                _ => false,
            };
            if frame {
                seen.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
            gst::PadProbeReturn::Ok
        },
    );
    count
}

#[test]
fn a_slow_predicted_monitor_branch_gets_every_frame_when_not_live() {
    // Recording the relit video while the predicted monitor plays at its own pace:
    // the side branch is slower than the element, and must still get a frame or a
    // gap for every face frame.
    init();
    let frames = 40;
    let pipeline = gst::parse::launch(&format!(
        "videotestsrc num-buffers={frames} ! video/x-raw,width=160,height=120,framerate=30/1 \
         ! lsydrelight name=r  r.src ! queue ! fakesink name=main sync=false \
         r.monitor_src ! queue max-size-buffers=2 ! identity sleep-time=30000 \
         ! fakesink name=side sync=false"
    ))
    .unwrap()
    .downcast::<gst::Bin>()
    .unwrap();
    let side = pipeline
        .by_name("side")
        .unwrap()
        .static_pad("sink")
        .unwrap();
    let main = pipeline
        .by_name("main")
        .unwrap()
        .static_pad("sink")
        .unwrap();
    let (side_frames, main_frames) = (count_frames(&side), count_frames(&main));
    pipeline.set_state(gst::State::Playing).unwrap();
    let msg = pipeline
        .bus()
        .unwrap()
        .timed_pop_filtered(
            gst::ClockTime::from_seconds(60),
            &[gst::MessageType::Error, gst::MessageType::Eos],
        )
        .expect("the pipeline ends");
    let e = pipeline.by_name("r").unwrap();
    pipeline.set_state(gst::State::Null).unwrap();
    assert!(matches!(msg.view(), gst::MessageView::Eos(_)), "{msg:?}");
    let load = std::sync::atomic::Ordering::SeqCst;
    assert_eq!(main_frames.load(load), frames);
    assert_eq!(side_frames.load(load), frames, "monitor_src dropped frames");
    assert_eq!(stat(&e, "monitor-dropped"), 0);
}

#[test]
fn an_off_centre_face_is_followed_and_an_empty_frame_passes() {
    // A person sitting left of centre in a wide frame: the relit square follows the
    // face (the ROI meta says where), and pixels far from it are left alone.
    let (w, h) = (640u32, 360u32);
    let left = State {
        pose: Pose {
            body: Vec3::new(-0.25, 0.03, 0.0),
            ..Pose::default()
        },
        ..State::default()
    };
    let img = render_person(&left, Vec3::new(1.0, 1.0, 1.0), w, h);
    let e = element();
    e.set_property("target-location", target("left-key"));
    let mut harness = Harness::with_element(&e, Some("sink"), Some("src"));
    let c = caps(gst_video::VideoFormat::Rgb, w, h, 30);
    harness.set_src_caps(c.clone());
    harness
        .push(buffer(&img, &c, frame_time(0), FRAME))
        .unwrap();
    let out = harness.pull().unwrap();
    let roi = out
        .meta::<gst_video::VideoRegionOfInterestMeta>()
        .expect("the relit square is marked");
    assert_eq!(roi.roi_type(), "face");
    let (x, _, side, _) = roi.rect();
    let centre = x + side / 2;
    assert!(
        centre + 40 < w / 2,
        "the square is centred at x = {centre}, not on the person left of centre"
    );
    let (before, after) = (
        to_rgb(&buffer(&img, &c, frame_time(0), FRAME), &c),
        to_rgb(&out, &c),
    );
    assert!(mean_abs_diff(&before, &after) > 1.0, "the face is relit");
    let right_edge_changed = (0..h as usize)
        .flat_map(|y| {
            let row = (y * w as usize + w as usize - 20) * 3;
            row..row + 60
        })
        .filter(|&i| before.data[i] != after.data[i])
        .count();
    assert_eq!(right_edge_changed, 0, "far from the face nothing changes");
    assert_eq!(stat(&e, "face-detections"), 1);

    // Nobody in view: the frame passes untouched, with no network run.
    let empty = deskstage::monitor::RgbImage {
        width: w as usize,
        height: h as usize,
        data: vec![90; (w * h * 3) as usize],
    };
    let e2 = element();
    let mut h2 = Harness::with_element(&e2, Some("sink"), Some("src"));
    h2.set_src_caps(c.clone());
    let input = buffer(&empty, &c, frame_time(0), FRAME);
    h2.push(input.clone()).unwrap();
    let out = h2.pull().unwrap();
    assert!(
        out.map_readable().unwrap().as_slice() == input.map_readable().unwrap().as_slice(),
        "a frame with no face is left as it is"
    );
    assert_eq!(stat(&e2, "skipped-no-face"), 1);
    assert_eq!(stat(&e2, "relit"), 0);
}

/// `stats` names where a frame's time goes: every stage is counted once, within
/// the element's processing, which is within the frame's whole turn.
#[test]
fn a_frame_upstream_still_holds_is_copied_and_left_as_it_was() {
    let (e, mut h) = face_harness(gst_video::VideoFormat::I420);
    let c = caps(gst_video::VideoFormat::I420, FACE_W, FACE_H, 30);
    // Held here too, as a `tee` before the element holds it for its other branch.
    let held = buffer(face_rgb(), &c, frame_time(0), FRAME);
    let before = to_rgb(&held, &c);
    h.push(held.clone()).unwrap();
    let relit = h.pull().unwrap();
    assert!(
        mean_abs_diff(&to_rgb(&relit, &c), &before) > 0.5,
        "the frame is relit"
    );
    assert_eq!(
        mean_abs_diff(&to_rgb(&held, &c), &before),
        0.0,
        "the frame upstream holds is not written"
    );
    assert_eq!(stat(&e, "frames-copied"), 1);
    let copy = e
        .property::<gst::Structure>("stats")
        .get::<f64>("copy-seconds")
        .unwrap();
    assert!(copy > 0.0, "the copy's time is counted");
    // A frame the element alone holds is written where it is.
    h.push(buffer(face_rgb(), &c, frame_time(1), FRAME))
        .unwrap();
    h.pull().unwrap();
    assert_eq!(stat(&e, "frames-copied"), 1);
}

/// A target on part of the screen runs the decoder again with it spread evenly
/// every 4th network frame (`spread-decodes`), so the face takes its mean colour;
/// `spread-colour=false` never does.
#[test]
fn spread_colour_decodes_again_every_fourth_network_frame_unless_turned_off() {
    for (on, decodes) in [(true, 2), (false, 0)] {
        let (e, mut h) = face_harness(gst_video::VideoFormat::I420);
        let c = caps(gst_video::VideoFormat::I420, FACE_W, FACE_H, 30);
        e.set_property("reuse-interval", 1u32);
        e.set_property("spread-colour", on);
        e.set_property_from_str("target-preset", "warm-key-left");
        for i in 0..8 {
            h.push(buffer(face_rgb(), &c, frame_time(i), FRAME))
                .unwrap();
            h.pull().unwrap();
        }
        assert_eq!(stat(&e, "relit"), 8, "spread-colour={on}");
        assert_eq!(stat(&e, "spread-decodes"), decodes, "spread-colour={on}");
    }
}

#[test]
fn stats_account_for_the_time_stage_by_stage() {
    let (e, mut h) = face_harness(gst_video::VideoFormat::I420);
    let c = caps(gst_video::VideoFormat::I420, FACE_W, FACE_H, 30);
    for i in 0..6 {
        h.push(buffer(face_rgb(), &c, frame_time(i), FRAME))
            .unwrap();
        h.pull().unwrap();
    }
    let stats = e.property::<gst::Structure>("stats");
    let seconds = |field: &str| {
        let s = stats
            .get::<f64>(field)
            .unwrap_or_else(|_| panic!("stats has no {field}"));
        assert!(s >= 0.0, "{field} is {s}");
        s
    };
    let stages = [
        "face-seconds",
        "crop-seconds",
        "network-seconds",
        "smoothing-seconds",
        "change-seconds",
        "decide-seconds",
        "paste-seconds",
        "copy-seconds",
        "setup-seconds",
        "finish-seconds",
    ];
    let named: f64 = stages.iter().map(|s| seconds(s)).sum();
    let processing = seconds("processing-seconds");
    assert!(
        named <= processing * 1.001,
        "the stages add up to {named} s, more than the {processing} s of processing"
    );
    assert!(processing <= seconds("frame-seconds"));
    for busy in [
        "network-seconds",
        "change-seconds",
        "paste-seconds",
        "crop-seconds",
    ] {
        assert!(seconds(busy) > 0.0, "{busy} counted nothing");
    }
    // Same picture, same light: the network ran every 3rd frame, and the frames
    // between carried its change without building another.
    assert_eq!(stat(&e, "relit"), 2);
    assert_eq!(stat(&e, "reused-interval"), 4);
}
