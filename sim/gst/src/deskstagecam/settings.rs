//! What the user set: the element's properties, their defaults and ParamSpecs.

use std::sync::LazyLock;

use deskstage::webcam::{self, WebcamSettings};
use gst::glib;
use gst::prelude::*;

use super::Motion;

const DEFAULT_FPS: u32 = 10;
const MAX_SIZE: u32 = 1920;

#[derive(Debug, Clone)]
pub struct Settings {
    pub webcam: WebcamSettings,
    /// Most camera frames a second.
    pub fps: u32,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            webcam: WebcamSettings::default(),
            fps: DEFAULT_FPS,
        }
    }
}

pub fn properties() -> &'static [glib::ParamSpec] {
    static PROPERTIES: LazyLock<Vec<glib::ParamSpec>> = LazyLock::new(|| {
        let d = Settings::default();
        vec![
            glib::ParamSpecUInt64::builder("subject")
                .nick("Subject")
                .blurb("Who is filmed: the simulated person's seed")
                .default_value(d.webcam.subject_seed)
                .mutable_ready()
                .build(),
            glib::ParamSpecUInt64::builder("seed")
                .nick("Seed")
                .blurb("Their motion, outfit and room-light direction")
                .default_value(d.webcam.seed)
                .mutable_ready()
                .build(),
            glib::ParamSpecDouble::builder("room-light")
                .nick("Room light")
                .blurb(
                    "Room light at the face relative to a full-white monitor's: desks are \
                     about 0.1 to 0.35; above 1 the room overpowers the monitor",
                )
                .minimum(0.0)
                .maximum(100.0)
                .default_value(d.webcam.room_light as f64)
                .mutable_ready()
                .build(),
            glib::ParamSpecEnum::builder_with_default("motion", Motion::Natural)
                .nick("Motion")
                .blurb("How the person moves: natural, or frozen in one pose and expression")
                .mutable_ready()
                .build(),
            glib::ParamSpecDouble::builder("away-after")
                .nick("Away after")
                .blurb("Seconds of running time after which the person leaves the frame; -1: never")
                .minimum(-1.0)
                .maximum(f64::MAX)
                .default_value(-1.0)
                .mutable_ready()
                .build(),
            glib::ParamSpecUInt::builder("width")
                .nick("Width")
                .blurb("Width of the camera video in pixels")
                .minimum(16)
                .maximum(MAX_SIZE)
                .default_value(d.webcam.width as u32)
                .mutable_ready()
                .build(),
            glib::ParamSpecUInt::builder("height")
                .nick("Height")
                .blurb("Height of the camera video in pixels")
                .minimum(16)
                .maximum(MAX_SIZE)
                .default_value(d.webcam.height as u32)
                .mutable_ready()
                .build(),
            glib::ParamSpecUInt::builder("fps")
                .nick("Frames per second")
                .blurb("Most camera frames a second; screen frames in between are dropped")
                .minimum(1)
                .maximum(120)
                .default_value(d.fps)
                .mutable_ready()
                .build(),
        ]
    });
    PROPERTIES.as_ref()
}

impl Settings {
    pub fn set(&mut self, value: &glib::Value, pspec: &glib::ParamSpec) {
        let w = &mut self.webcam;
        match pspec.name() {
            "subject" => w.subject_seed = value.get().expect("type checked upstream"),
            "seed" => w.seed = value.get().expect("type checked upstream"),
            "room-light" => {
                w.room_light = value.get::<f64>().expect("type checked upstream") as f32
            }
            "motion" => {
                w.motion = match value.get::<Motion>().expect("type checked upstream") {
                    Motion::Natural => webcam::Motion::Natural,
                    Motion::Frozen => webcam::Motion::Frozen,
                }
            }
            "away-after" => {
                let t: f64 = value.get().expect("type checked upstream");
                w.away_after = (t >= 0.0).then_some(t);
            }
            "width" => w.width = value.get::<u32>().expect("type checked upstream") as usize,
            "height" => w.height = value.get::<u32>().expect("type checked upstream") as usize,
            "fps" => self.fps = value.get().expect("type checked upstream"),
            other => unreachable!("no property {other}"),
        }
    }

    pub fn get(&self, pspec: &glib::ParamSpec) -> glib::Value {
        let w = &self.webcam;
        match pspec.name() {
            "subject" => w.subject_seed.to_value(),
            "seed" => w.seed.to_value(),
            "room-light" => (w.room_light as f64).to_value(),
            "motion" => match w.motion {
                webcam::Motion::Natural => Motion::Natural,
                webcam::Motion::Frozen => Motion::Frozen,
            }
            .to_value(),
            "away-after" => w.away_after.unwrap_or(-1.0).to_value(),
            "width" => (w.width as u32).to_value(),
            "height" => (w.height as u32).to_value(),
            "fps" => self.fps.to_value(),
            other => unreachable!("no property {other}"),
        }
    }
}
