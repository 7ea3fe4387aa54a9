use std::sync::{LazyLock, Mutex, MutexGuard};

use deskstage::webcam::{Webcam, screen_light};
use gst::glib;
use gst::subclass::prelude::*;
use gst_base::subclass::prelude::*;
use gst_video::VideoFormat;
use gst_video::prelude::*;
use gst_video::subclass::prelude::*;

use super::settings::{self, Settings};

static CAT: LazyLock<gst::DebugCategory> = LazyLock::new(|| {
    gst::DebugCategory::new(
        "deskstagecam",
        gst::DebugColorFlags::empty(),
        Some("Simulated webcam of a desk light stage"),
    )
});

/// The packed 8-bit RGB formats the screen may come in: each with the byte
/// offsets of red, green and blue in a pixel, and the pixel's size.
const SCREEN_FORMATS: [(VideoFormat, [usize; 3], usize); 10] = [
    (VideoFormat::Rgb, [0, 1, 2], 3),
    (VideoFormat::Bgr, [2, 1, 0], 3),
    (VideoFormat::Rgbx, [0, 1, 2], 4),
    (VideoFormat::Bgrx, [2, 1, 0], 4),
    (VideoFormat::Xrgb, [1, 2, 3], 4),
    (VideoFormat::Xbgr, [3, 2, 1], 4),
    (VideoFormat::Rgba, [0, 1, 2], 4),
    (VideoFormat::Bgra, [2, 1, 0], 4),
    (VideoFormat::Argb, [1, 2, 3], 4),
    (VideoFormat::Abgr, [3, 2, 1], 4),
];

fn screen_caps() -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format_list(SCREEN_FORMATS.map(|(f, _, _)| f))
        .build()
}

fn camera_caps() -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(VideoFormat::Rgb)
        .build()
}

/// What a run of the element knows once the caps are set.
struct State {
    webcam: Webcam,
    /// Red, green and blue offsets in a screen pixel, and its size.
    layout: ([usize; 3], usize),
    /// Nanoseconds between camera frames.
    interval: u64,
    /// Running time from which the next screen frame is filmed.
    next_due: Option<u64>,
    filmed: u64,
}

#[derive(Default)]
pub struct DeskstageCam {
    settings: Mutex<Settings>,
    state: Mutex<Option<State>>,
}

impl DeskstageCam {
    fn settings(&self) -> MutexGuard<'_, Settings> {
        self.settings.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn state(&self) -> MutexGuard<'_, Option<State>> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[glib::object_subclass]
impl ObjectSubclass for DeskstageCam {
    const NAME: &'static str = "GstDeskstageCam";
    type Type = super::DeskstageCam;
    type ParentType = gst_video::VideoFilter;
}

impl ObjectImpl for DeskstageCam {
    fn properties() -> &'static [glib::ParamSpec] {
        settings::properties()
    }

    fn set_property(&self, _id: usize, value: &glib::Value, pspec: &glib::ParamSpec) {
        gst::debug!(CAT, imp = self, "{} set to {value:?}", pspec.name());
        self.settings().set(value, pspec);
    }

    fn property(&self, _id: usize, pspec: &glib::ParamSpec) -> glib::Value {
        self.settings().get(pspec)
    }
}

impl GstObjectImpl for DeskstageCam {}

impl ElementImpl for DeskstageCam {
    fn metadata() -> Option<&'static gst::subclass::ElementMetadata> {
        static METADATA: LazyLock<gst::subclass::ElementMetadata> = LazyLock::new(|| {
            gst::subclass::ElementMetadata::new(
                "Simulated desk webcam",
                "Filter/Effect/Video",
                "Films a simulated person lit by the screen video it is given and by the room",
                "lsydrelight developers",
            )
        });
        Some(&*METADATA)
    }

    fn pad_templates() -> &'static [gst::PadTemplate] {
        static TEMPLATES: LazyLock<Vec<gst::PadTemplate>> = LazyLock::new(|| {
            let pad = |name, direction, caps: gst::Caps| {
                gst::PadTemplate::new(name, direction, gst::PadPresence::Always, &caps)
                    .expect("valid pad template")
            };
            vec![
                pad("sink", gst::PadDirection::Sink, screen_caps()),
                pad("src", gst::PadDirection::Src, camera_caps()),
            ]
        });
        TEMPLATES.as_ref()
    }
}

impl BaseTransformImpl for DeskstageCam {
    const MODE: gst_base::subclass::BaseTransformMode =
        gst_base::subclass::BaseTransformMode::NeverInPlace;
    const PASSTHROUGH_ON_SAME_CAPS: bool = false;
    const TRANSFORM_IP_ON_PASSTHROUGH: bool = false;

    /// The camera's size and rate are the properties', whatever the screen's.
    fn transform_caps(
        &self,
        direction: gst::PadDirection,
        caps: &gst::Caps,
        filter: Option<&gst::Caps>,
    ) -> Option<gst::Caps> {
        let s = self.settings().clone();
        let template = match direction {
            gst::PadDirection::Sink => gst_video::VideoCapsBuilder::new()
                .format(VideoFormat::Rgb)
                .width(s.webcam.width as i32)
                .height(s.webcam.height as i32)
                .pixel_aspect_ratio(gst::Fraction::new(1, 1))
                .framerate(gst::Fraction::new(s.fps as i32, 1))
                .build(),
            _ => screen_caps(),
        };
        // Any screen caps give the one camera caps, and the other way round.
        let out = if caps.is_empty() {
            gst::Caps::new_empty()
        } else {
            template
        };
        gst::debug!(CAT, imp = self, "{direction:?} caps {caps} give {out}");
        Some(match filter {
            Some(f) => f.intersect_with_mode(&out, gst::CapsIntersectMode::First),
            None => out,
        })
    }

    fn stop(&self) -> Result<(), gst::ErrorMessage> {
        *self.state() = None;
        Ok(())
    }
}

impl VideoFilterImpl for DeskstageCam {
    fn set_info(
        &self,
        _incaps: &gst::Caps,
        in_info: &gst_video::VideoInfo,
        _outcaps: &gst::Caps,
        out_info: &gst_video::VideoInfo,
    ) -> Result<(), gst::LoggableError> {
        let s = self.settings().clone();
        let layout = SCREEN_FORMATS
            .iter()
            .find(|(f, _, _)| *f == in_info.format())
            .map(|&(_, offsets, size)| (offsets, size))
            .ok_or_else(|| {
                gst::loggable_error!(
                    CAT,
                    "screen format {:?} is not packed RGB",
                    in_info.format()
                )
            })?;
        let webcam = Webcam::new(deskstage::webcam::WebcamSettings {
            width: out_info.width() as usize,
            height: out_info.height() as usize,
            ..s.webcam
        })
        .map_err(|e| gst::loggable_error!(CAT, "cannot set up the simulated webcam: {e}"))?;
        gst::info!(
            CAT,
            imp = self,
            "filming subject {} at {}x{}, {} fps, room light {}, {:?}, away after {:?}",
            s.webcam.subject_seed,
            out_info.width(),
            out_info.height(),
            s.fps,
            s.webcam.room_light,
            s.webcam.motion,
            s.webcam.away_after
        );
        *self.state() = Some(State {
            webcam,
            layout,
            interval: 1_000_000_000 / s.fps as u64,
            next_due: None,
            filmed: 0,
        });
        Ok(())
    }

    fn transform_frame(
        &self,
        inframe: &gst_video::VideoFrameRef<&gst::BufferRef>,
        outframe: &mut gst_video::VideoFrameRef<&mut gst::BufferRef>,
    ) -> Result<gst::FlowSuccess, gst::FlowError> {
        let mut guard = self.state();
        let state = guard.as_mut().ok_or(gst::FlowError::NotNegotiated)?;
        let segment = self.obj().segment();
        let running = segment
            .downcast_ref::<gst::ClockTime>()
            .and_then(|s| s.to_running_time(inframe.buffer().pts()))
            .map(|t| t.nseconds());
        // Without a timestamp a frame counts as the next due one.
        let at = running.unwrap_or_else(|| state.next_due.unwrap_or(0));
        if state.next_due.is_some_and(|due| at < due) {
            gst::trace!(
                CAT,
                imp = self,
                "screen frame at {at} ns before the next camera frame"
            );
            return Ok(gst_base::BASE_TRANSFORM_FLOW_DROPPED);
        }
        // The next frame is due one interval after this one was; after a lag
        // (a slow screen), one interval from now rather than a burst.
        let next = state.next_due.unwrap_or(at) + state.interval;
        state.next_due = Some(if next > at { next } else { at + state.interval });

        let (offsets, size) = state.layout;
        let stride = inframe.plane_stride()[0] as usize;
        let data = inframe.plane_data(0).map_err(|_| gst::FlowError::Error)?;
        let monitor = state.webcam.monitor();
        let light = screen_light(
            inframe.width() as usize,
            inframe.height() as usize,
            monitor.rows,
            monitor.cols,
            |x, y| offsets.map(|o| data[y * stride + x * size + o]),
        );
        let image = state.webcam.frame(at as f64 / 1e9, state.filmed, &light);
        state.filmed += 1;

        let out_stride = outframe.plane_stride()[0] as usize;
        let out = outframe
            .plane_data_mut(0)
            .map_err(|_| gst::FlowError::Error)?;
        let row = image.width * 3;
        for (y, src) in image.data.chunks_exact(row).enumerate() {
            out[y * out_stride..y * out_stride + row].copy_from_slice(src);
        }
        Ok(gst::FlowSuccess::Ok)
    }
}
