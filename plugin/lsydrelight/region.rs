//! The face region of each frame: the square the network sees. With
//! `face-tracking` (the default) it follows the face with the face detector and
//! tracker ([`crate::face`]), fading the relighting in and out as a face comes
//! and goes; without, `crop-x`, `crop-y` and `crop-size` fix it.

use std::time::Instant;

use crate::engine::CropSpec;
use crate::engine::EngineError;
use crate::face::detector::SearchStep;
use crate::face::{
    CropRule, DetectorError, FaceBox, FaceDetector, FaceTracker, TrackerSettings, face_place,
};
use crate::frame::{Crop, FacePlace, Frame};

use super::settings::Settings;

/// One frame's face region.
pub struct Region {
    pub crop: Crop,
    /// Where the face is in the crop: the rule's place, or higher or lower
    /// where the crop was moved to stay inside the frame.
    pub face: FacePlace,
    /// How much of the relighting to show, in [0, 1]; 0 with no face.
    pub strength: f32,
    /// The followed face, when the detector ran on this frame.
    pub detected: Option<FaceBox>,
    /// Where the detector looked beyond the whole frame, when it ran.
    pub search: Option<SearchStep>,
}

/// Work done following the face, for statistics.
#[derive(Clone, Copy, Debug, Default)]
pub struct FollowCounts {
    pub detections: u64,
    /// Seconds in the detector and the tracker.
    pub seconds: f64,
}

pub struct FaceRegion {
    follower: Option<(FaceDetector, FaceTracker)>,
    tracker_settings: TrackerSettings,
    counts: FollowCounts,
}

impl FaceRegion {
    /// Loads the detector when the face is to be followed; `crop` is the model's rule.
    pub fn new(
        env: &ort::environment::Environment,
        settings: &Settings,
        crop: CropSpec,
    ) -> Result<FaceRegion, DetectorError> {
        let tracker_settings = TrackerSettings {
            face_index: settings.face_index as usize,
            crop: CropRule {
                side: crop.side,
                lift: crop.lift,
            },
            ..TrackerSettings::default()
        };
        let follower = if settings.face_tracking {
            let detector = FaceDetector::new(env, &settings.face_detector_location, 1)?;
            Some((detector, FaceTracker::new(tracker_settings)))
        } else {
            None
        };
        Ok(FaceRegion {
            follower,
            tracker_settings,
            counts: FollowCounts::default(),
        })
    }

    /// Forgets the followed face: a new stream, a seek, new caps.
    pub fn reset(&mut self) {
        if let Some((_, tracker)) = self.follower.as_mut() {
            *tracker = FaceTracker::new(self.tracker_settings);
        }
    }

    pub fn counts(&self) -> FollowCounts {
        self.counts
    }

    /// The region of `frame`, shown at `time` seconds.
    pub fn locate(
        &mut self,
        frame: &Frame,
        time: f64,
        settings: &Settings,
    ) -> Result<Region, EngineError> {
        let (width, height) = (frame.width, frame.height);
        let Some((detector, tracker)) = self.follower.as_mut() else {
            let manual = &settings.crop;
            let rule = self.tracker_settings.crop;
            return Ok(Region {
                crop: Crop::centred(width, height, manual.x, manual.y, manual.size),
                face: FacePlace::by_rule(rule.side, rule.lift),
                strength: 1.0,
                detected: None,
                search: None,
            });
        };
        let started = Instant::now();
        let tracked = tracker.track(frame, time, |f| detector.detect(f))?;
        self.counts.seconds += started.elapsed().as_secs_f64();
        if tracked.detected {
            self.counts.detections += 1;
        }
        let crop = tracked.square.crop(width, height);
        Ok(Region {
            crop,
            face: face_place(tracked.wanted, crop, self.tracker_settings.crop),
            strength: tracked.fade,
            detected: tracked.face.filter(|_| tracked.detected),
            search: tracked.detected.then_some(detector.last_search),
        })
    }
}
