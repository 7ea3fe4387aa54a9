//! The monitor-match check's place in the element: the face stream's window of
//! (screen, predicted) light pairs, and the element message that reports its
//! score about once a second. The scoring is [`crate::monitor_match`]'s.

use gst::prelude::*;
use gst::subclass::prelude::*;

use super::imp::{CAT, LsydRelight};
use super::lock;
use super::settings::Settings;
use crate::light::Light;
use crate::monitor_match::{MatchScore, MatchSettings, MatchWindow};

/// Name of the element message.
pub const MESSAGE_NAME: &str = "lsydrelight-monitor-match";
/// Seconds of stream time between messages.
const PERIOD: f64 = 1.0;

#[derive(Debug, Default)]
pub struct MatchCheck {
    window: MatchWindow,
    /// Stream time of the last message, seconds.
    last_report: Option<f64>,
}

impl MatchCheck {
    /// Forgets the stream's past: after a flush, a seek or a new stream.
    pub fn reset(&mut self) {
        self.window.reset();
        self.last_report = None;
    }

    /// Notes a face frame at `time` (running time, seconds): with the screen's light
    /// and the one predicted from the face, when both are known. Returns the score
    /// when a message is due.
    pub fn frame(
        &mut self,
        time: f64,
        pair: Option<(&Light, &Light)>,
        settings: &MatchSettings,
        fps: f64,
    ) -> Option<MatchScore> {
        if self.last_report.is_some_and(|t| time < t) {
            // Time went back without a flush: start afresh.
            self.reset();
        }
        match pair {
            Some((screen, predicted)) => self.window.push(time, screen, predicted, settings.window),
            None => self.window.advance(time, settings.window),
        }
        let last = *self.last_report.get_or_insert(time);
        if time - last < PERIOD - 1e-6 {
            return None;
        }
        self.last_report = Some(time);
        Some(self.window.score(settings, fps))
    }
}

/// The element message of one score.
pub fn message_structure(
    score: &MatchScore,
    settings: &MatchSettings,
    running_time: gst::ClockTime,
) -> gst::Structure {
    let mut s = gst::Structure::builder(MESSAGE_NAME)
        .field("verdict", score.verdict.name())
        .field("window", settings.window)
        .field("threshold", settings.threshold)
        .field("frames", score.frames as u32)
        .field("span", score.span)
        .field("running-time", running_time)
        .build();
    // A score or component that cannot be computed (a still screen) is left out.
    if let Some(v) = score.score {
        s.set("score", v);
    }
    for (component, value) in &score.components {
        if let Some(v) = value {
            s.set(component.name(), *v);
        }
    }
    s
}

impl LsydRelight {
    /// Adds a face frame to the monitor-match check, and posts its message when due.
    pub(super) fn check_match(
        &self,
        time: f64,
        pair: Option<(Light, Light)>,
        fps: f64,
        settings: &Settings,
    ) {
        let pair = pair.as_ref().map(|(screen, predicted)| (screen, predicted));
        let Some(score) = lock(&self.match_check).frame(time, pair, &settings.matching, fps) else {
            return;
        };
        gst::debug!(
            CAT,
            imp = self,
            "monitor match at {time:.2} s: {} over {} frames, score {:?}, components {:?}",
            score.verdict.name(),
            score.frames,
            score.score,
            score.components
        );
        let structure = message_structure(
            &score,
            &settings.matching,
            gst::ClockTime::from_seconds_f64(time),
        );
        let element = self.obj();
        let _ = element.post_message(
            gst::message::Element::builder(structure)
                .src(&*element)
                .build(),
        );
    }
}
