//! The crossfade between target lights: when the target changes while playing,
//! the light the network is given moves from the one in use to the new one over
//! `target-transition` of the face stream's running time, instead of jumping.
//! Lights, not their codes, are blended: a blend of two lights is what a monitor
//! crossfading between the two pictures shows, a light the network knows.

use crate::light::Light;

/// The target light in use, and the fade towards a new one if there is one.
#[derive(Debug, Default)]
pub struct Crossfade {
    current: Option<Light>,
    fade: Option<Fade>,
    /// A frame has been given the current light: changes from now on fade.
    shown: bool,
}

#[derive(Debug)]
struct Fade {
    from: Light,
    to: Light,
    /// Face running time (ns) at which the fade started; None until the first
    /// frame after the change names it.
    start: Option<u64>,
    duration: u64,
}

/// Linear blend of two lights, `t` of the way from `a` to `b`.
pub fn blend(a: &Light, b: &Light, t: f32) -> Light {
    Light(a.0.iter().zip(&b.0).map(|(x, y)| x + (y - x) * t).collect())
}

impl Crossfade {
    /// Sets the light at once, with no fade: the first target of a run, or a
    /// target that follows a video stream frame by frame.
    pub fn jump(&mut self, light: Light) {
        self.current = Some(light);
        self.fade = None;
    }

    /// Starts a fade from the light in use (mid-fade, the blend shown now) to
    /// `light`, lasting `duration` ns of face running time from the next frame.
    /// Before any frame was shown a light there is nothing to fade from.
    pub fn retarget(&mut self, light: Light, duration: u64) {
        let Some(current) = self.current.clone().filter(|_| self.shown) else {
            return self.jump(light);
        };
        if duration == 0 {
            return self.jump(light);
        }
        self.fade = Some(Fade {
            from: current,
            to: light,
            start: None,
            duration,
        });
    }

    /// The light for the face frame at running time `rt` (ns); None before any
    /// target is set. Frames without a timestamp advance the fade by nothing.
    pub fn at(&mut self, rt: Option<u64>) -> Option<&Light> {
        self.shown |= self.current.is_some();
        if let Some(fade) = self.fade.as_mut() {
            let start = *fade.start.get_or_insert(rt.unwrap_or(0));
            let elapsed = rt.map_or(0, |t| t.saturating_sub(start));
            if elapsed >= fade.duration {
                let done = self.fade.take().expect("a fade");
                self.current = Some(done.to);
            } else {
                let t = elapsed as f32 / fade.duration as f32;
                self.current = Some(blend(&fade.from, &fade.to, t));
            }
        }
        self.current.as_ref()
    }

    /// Whether a fade is under way.
    pub fn fading(&self) -> bool {
        self.fade.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_change_fades_linearly_over_the_transition_then_holds() {
        let mut fade = Crossfade::default();
        assert!(fade.at(Some(0)).is_none());
        fade.jump(Light::uniform([0.0; 3]));
        fade.at(Some(0));
        fade.retarget(Light::uniform([1.0; 3]), 500 * MS);
        // The first frame after the change starts the fade at its own time.
        assert_eq!(fade.at(Some(1000 * MS)).unwrap().0[0], 0.0);
        let quarter = fade.at(Some(1125 * MS)).unwrap().0[0];
        assert!((quarter - 0.25).abs() < 1e-6, "{quarter}");
        assert!(fade.fading());
        assert_eq!(fade.at(Some(1500 * MS)).unwrap().0[0], 1.0);
        assert!(!fade.fading());
        assert_eq!(fade.at(Some(9000 * MS)).unwrap().0[0], 1.0);
    }

    #[test]
    fn a_change_mid_fade_starts_from_the_light_shown_so_nothing_jumps() {
        let mut fade = Crossfade::default();
        fade.jump(Light::uniform([0.0; 3]));
        fade.at(Some(0));
        fade.retarget(Light::uniform([1.0; 3]), 400 * MS);
        fade.at(Some(0));
        let mid = fade.at(Some(200 * MS)).unwrap().0[0];
        assert!((mid - 0.5).abs() < 1e-6);
        fade.retarget(Light::uniform([0.0; 3]), 400 * MS);
        let mut last = mid;
        for i in 1..=30 {
            let v = fade.at(Some((200 + 20 * i) * MS)).unwrap().0[0];
            assert!(
                (v - last).abs() <= 0.5 * 20.0 / 400.0 + 1e-6,
                "step {i}: {last} -> {v}"
            );
            last = v;
        }
        assert_eq!(last, 0.0);
    }

    #[test]
    fn no_transition_or_no_previous_target_or_no_frame_yet_jumps() {
        let mut fade = Crossfade::default();
        fade.retarget(Light::uniform([0.3; 3]), 500 * MS);
        // A change before the first frame: that frame has the new light.
        fade.retarget(Light::uniform([0.5; 3]), 500 * MS);
        assert_eq!(fade.at(Some(0)).unwrap().0[0], 0.5);
        fade.retarget(Light::uniform([0.3; 3]), 500 * MS);
        assert!(fade.fading());
        fade.jump(Light::uniform([0.3; 3]));
        assert_eq!(fade.at(Some(0)).unwrap().0[0], 0.3);
        fade.retarget(Light::uniform([0.7; 3]), 0);
        assert_eq!(fade.at(Some(1)).unwrap().0[0], 0.7);
    }
}
