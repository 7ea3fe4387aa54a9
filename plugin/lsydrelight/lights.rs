//! Where each face frame's lights come from beside the face stream: the source
//! light from the monitor stream ([`super::monitor`]) and the target light from
//! the video target (`target_sink`), each aligned by running time, with the
//! messages when either falls back or comes back; and the watch that warns
//! when face frames wait for a silent monitor stream in a non-live pipeline.

use std::sync::Mutex;
use std::time::Duration;

use gst::prelude::*;
use gst::subclass::prelude::*;
use gst_base::prelude::*;

use super::imp::{CAT, LsydRelight};
use super::lock;
use super::monitor::{Decision, Fallback, MonitorTrack, Reading, Transition};
use super::settings::Settings;
use crate::engine::Source;
use crate::light::Light;
use crate::targets::Preset;

/// How often the element looks whether face frames wait for a silent monitor stream.
const MONITOR_WATCH_PERIOD: gst::ClockTime = gst::ClockTime::from_mseconds(200);

impl LsydRelight {
    /// The source light of the face frame at `face_rt`, and the running time of the
    /// monitor frame it came from; None to wait for more monitor data.
    pub(super) fn source_light(
        &self,
        face_rt: Option<gst::ClockTime>,
        deadline: bool,
        settings: &Settings,
    ) -> Option<(Source, Option<i64>)> {
        let mut reading = Reading::default();
        // The pad slot before the track, as everywhere: never the other way round.
        let pad = self.monitor_pad();
        let mut track = lock(&self.monitor);
        let decision = match pad {
            Some(pad) => track.consume(
                &pad,
                face_rt,
                deadline,
                settings.monitor_offset,
                settings.monitor_timeout,
                &mut reading,
            ),
            None => Decision::Fallback(Fallback::NoMonitorPad),
        };
        self.count(|st| st.monitor.add(&reading));
        let (fallback, result) = match decision {
            Decision::Wait => {
                gst::trace!(
                    CAT,
                    imp = self,
                    "face frame at {}: waiting for monitor frames",
                    face_rt.display()
                );
                return None;
            }
            Decision::Known(light, at) => {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face frame at {}: source light from the monitor frame shown at {} ({} consumed)",
                    face_rt.display(),
                    gst::ClockTime::from_nseconds(at.max(0) as u64),
                    reading.frames
                );
                (None, (Source::Known(light), Some(at)))
            }
            Decision::Fallback(Fallback::NoMonitorPad)
                if settings.source_preset != Preset::None =>
            {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face frame at {}: no monitor stream: source light {}, as source-preset says",
                    face_rt.display(),
                    settings.source_preset.nick()
                );
                self.count(|st| st.assumed_source += 1);
                let light = settings.source_preset.light();
                (Some(Fallback::NoMonitorPad), (Source::Known(light), None))
            }
            Decision::Fallback(f) => {
                gst::debug!(
                    CAT,
                    imp = self,
                    "face frame at {}: predicting the source light: {}",
                    face_rt.display(),
                    f.describe()
                );
                (Some(f), (Source::Unknown, None))
            }
        };
        let transition = track.note_fallback(fallback);
        drop(track);
        match transition {
            Some(Transition::FallbackStarted(f)) => {
                self.count(|st| st.fallbacks += 1);
                gst::element_imp_warning!(
                    self,
                    gst::StreamError::Failed,
                    (
                        "Relighting with the predicted source light: {}",
                        f.describe()
                    ),
                    [
                        "Connect or restart the monitor stream; relighting follows it again as soon as it returns."
                    ]
                );
            }
            Some(Transition::Returned) => gst::element_imp_info!(
                self,
                gst::StreamError::Failed,
                ("The monitor stream is back: relighting with the monitor's light again")
            ),
            None => {}
        }
        Some(result)
    }

    /// The monitor-stream track of a sink pad that is not the face pad.
    pub(super) fn track_of(&self, pad: &gst_base::AggregatorPad) -> &Mutex<MonitorTrack> {
        if lock(&self.target_pad).as_ref() == Some(pad) {
            &self.target_track
        } else {
            &self.monitor
        }
    }

    /// The video target's light for the face frame at `face_rt`, aligned by running
    /// time as the monitor stream is: Some(None) keeps the target in use (no video
    /// target, or it has not started, stalled or ended); None waits for more data.
    pub(super) fn video_target(
        &self,
        face_rt: Option<gst::ClockTime>,
        deadline: bool,
        settings: &Settings,
    ) -> Option<Option<Light>> {
        let Some(pad) = lock(&self.target_pad).clone() else {
            return Some(None);
        };
        let mut reading = Reading::default();
        let mut track = lock(&self.target_track);
        let decision = track.consume(
            &pad,
            face_rt,
            deadline,
            0,
            settings.monitor_timeout,
            &mut reading,
        );
        self.count(|st| st.target_stream.add(&reading));
        let (light, fallback) = match decision {
            Decision::Wait => return None,
            Decision::Known(light, _) => (Some(light), None),
            Decision::Fallback(f) => (None, Some(f)),
        };
        let transition = track.note_fallback(fallback);
        drop(track);
        match transition {
            Some(Transition::FallbackStarted(f)) if f != Fallback::NotStarted => {
                gst::element_imp_warning!(
                    self,
                    gst::StreamError::Failed,
                    (
                        "Keeping the last target light: {}",
                        f.describe().replace("monitor", "target")
                    ),
                    ["Relighting follows the target stream again as soon as it sends frames."]
                )
            }
            Some(Transition::Returned) => {
                gst::debug!(CAT, imp = self, "the target stream is back")
            }
            _ => gst::trace!(CAT, imp = self, "video target at {}", face_rt.display()),
        }
        Some(light)
    }

    /// In a non-live pipeline the aggregator waits for data on every pad, so a
    /// monitor branch that never produces would hold the face stream forever with
    /// no word. Run every `MONITOR_WATCH_PERIOD` from the system clock.
    pub(super) fn watch_monitor(&self) {
        if self.qos.is_live() {
            return;
        }
        let Some(pad) = self.monitor_pad() else {
            return;
        };
        let timeout = Duration::from_nanos(lock(&self.settings).monitor_timeout.nseconds());
        let waiting = self.face_pad.has_buffer() && !pad.has_buffer() && !pad.is_eos();
        let mut track = lock(&self.monitor);
        if !waiting {
            track.flowing();
            return;
        }
        if track.newly_starved(timeout) {
            drop(track);
            gst::warning!(
                CAT,
                imp = self,
                "face frames wait for a silent monitor stream"
            );
            gst::element_imp_warning!(
                self,
                gst::StreamError::Failed,
                (
                    "Face frames are waiting for the monitor stream: monitor_sink has received nothing for {:.1} s",
                    timeout.as_secs_f64()
                ),
                [
                    "In a non-live pipeline lsydrelight waits for the monitor frame that lit each face frame. Check that the branch into monitor_sink produces frames (or ends with EOS), or release monitor_sink to relight with the predicted light."
                ]
            );
        }
    }

    pub(super) fn start_monitor_watch(&self) {
        let clock = gst::SystemClock::obtain();
        let id = clock.new_periodic_id(clock.time(), MONITOR_WATCH_PERIOD);
        let element = self.obj().downgrade();
        let scheduled = id.wait_async(move |_, _, _| {
            if let Some(element) = element.upgrade() {
                element.imp().watch_monitor();
            }
        });
        match scheduled {
            Ok(_) => *lock(&self.monitor_watch) = Some(id),
            Err(e) => gst::warning!(CAT, imp = self, "cannot watch the monitor stream: {e:?}"),
        }
    }

    pub(super) fn stop_monitor_watch(&self) {
        if let Some(id) = lock(&self.monitor_watch).take() {
            id.unschedule();
        }
    }
}
