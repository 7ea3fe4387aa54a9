//! A simulated webcam for live use: a person at the desk, lit by whatever the
//! screen shows at that moment plus the room light, moving as people do while
//! they watch videos. `sim/gst`'s `deskstagecam` element wraps it so that a
//! capture pipeline can film the simulated person as it would film a user.
//!
//! Unlike [`crate::dataset::Recording`], the monitor content is not chosen
//! here: each frame is rendered under the screen frame it is given, so the
//! camera video follows the content the capture tool records, exactly.

use crate::material::Look;
use crate::monitor::{CellLight, MonitorGeometry, RgbImage, srgb8_to_linear_table};
use crate::motion::{Range, Trajectory};
use crate::render::{Renderer, Scene, Sensor};
use crate::subject::{State, Subject};

/// How the simulated person moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// The paper's free capture: head turns of up to ±30° yaw and ±15° pitch,
    /// talking, smiling and blinking.
    Natural,
    /// Still as a photograph: one pose and expression throughout.
    Frozen,
}

/// Who is filmed, in which room, and how they behave.
#[derive(Clone, Debug, PartialEq)]
pub struct WebcamSettings {
    /// The person ([`Subject::from_seed`]).
    pub subject_seed: u64,
    /// Their motion, outfit and room-light direction.
    pub seed: u64,
    pub width: usize,
    pub height: usize,
    /// Room light at the face relative to a full-white monitor's. Real desks
    /// range from about 0.1 to 0.35; above 1 the room overpowers the monitor.
    pub room_light: f32,
    pub motion: Motion,
    /// Seconds after which the person gets up and leaves the frame for good.
    pub away_after: Option<f64>,
}

impl Default for WebcamSettings {
    fn default() -> Self {
        WebcamSettings {
            subject_seed: crate::subject::DEFAULT_SUBJECT_SEED,
            seed: 1,
            width: 320,
            height: 240,
            room_light: 0.2,
            motion: Motion::Natural,
            away_after: None,
        }
    }
}

/// The motion is planned this far ahead; later times repeat it.
const PLANNED_SECONDS: f64 = 3600.0;
/// Chance that a pose keyframe keeps the previous pose: people hold a pose for
/// a while, but a capture should keep moving.
const HOLD: f32 = 0.2;

/// The person, the room and the camera, ready to render frames.
pub struct Webcam {
    settings: WebcamSettings,
    renderer: Renderer,
    look: Look,
    motion: Trajectory,
    sensor: Sensor,
}

impl Webcam {
    pub fn new(settings: WebcamSettings) -> Result<Webcam, String> {
        if !(settings.room_light.is_finite() && settings.room_light >= 0.0) {
            return Err(format!(
                "room light {} is not a non-negative number",
                settings.room_light
            ));
        }
        if settings.width < 16 || settings.height < 16 {
            return Err(format!(
                "a {}x{} camera is too small: at least 16x16",
                settings.width, settings.height
            ));
        }
        let renderer = Renderer::new(Scene::new(
            Subject::from_seed(settings.subject_seed),
            settings.width,
            settings.height,
        ))?;
        let mut look = Look::random(settings.seed, "webcam-look");
        look.ambient.ratio = settings.room_light;
        let mut motion = Trajectory::random(
            settings.seed,
            "webcam-motion",
            PLANNED_SECONDS,
            Range::CAPTURE,
            HOLD,
        );
        if let Some(t) = settings.away_after {
            motion = motion.with_absence(t, f64::INFINITY);
        }
        Ok(Webcam {
            settings,
            renderer,
            look,
            motion,
            sensor: Sensor::default(),
        })
    }

    pub fn settings(&self) -> &WebcamSettings {
        &self.settings
    }

    /// The monitor's cell grid, which [`screen_light`] must produce.
    pub fn monitor(&self) -> &MonitorGeometry {
        &self.renderer.scene.monitor
    }

    /// The person's pose and expression `t` seconds into the capture.
    pub fn state(&self, t: f64) -> State {
        let planned = |t: f64| self.motion.state(t.max(0.0) % PLANNED_SECONDS);
        let mut state = match self.settings.motion {
            Motion::Natural => planned(t),
            Motion::Frozen => planned(0.0),
        };
        // Leaving is independent of the motion: a frozen person can leave too.
        state.pose.present = self.settings.away_after.is_none_or(|away| t < away);
        state
    }

    /// Frame `index`, `t` seconds into the capture, lit by `screen` (what the
    /// monitor shows) and the room: sensor noise included, as a webcam films it.
    pub fn frame(&self, t: f64, index: u64, screen: &CellLight) -> RgbImage {
        let transport = self.renderer.prepare(&self.look, &self.state(t));
        let image = self.renderer.render(&transport, &[screen]).remove(0);
        self.sensor.capture(&image, self.settings.seed, index)
    }
}

/// The light of a screen frame of any size on the monitor's `rows` × `cols`
/// cells: decoded to linear light and averaged over each cell's area (cells
/// cut pixels where the frame is not a multiple of the grid). `pixel(x, y)`
/// reads the frame's 8-bit sRGB.
pub fn screen_light(
    width: usize,
    height: usize,
    rows: usize,
    cols: usize,
    pixel: impl Fn(usize, usize) -> [u8; 3],
) -> CellLight {
    let lut = srgb8_to_linear_table();
    let xs = overlaps(width, cols);
    let ys = overlaps(height, rows);
    let mut sums = vec![crate::math::Vec3::ZERO; rows * cols];
    for (y, rows_of_y) in ys.iter().enumerate() {
        for (x, cols_of_x) in xs.iter().enumerate() {
            let [r, g, b] = pixel(x, y);
            let v = crate::math::Vec3::new(lut[r as usize], lut[g as usize], lut[b as usize]);
            for &(row, wy) in rows_of_y {
                for &(col, wx) in cols_of_x {
                    sums[row * cols + col] += v * (wx * wy);
                }
            }
        }
    }
    // Each cell covers width / cols by height / rows pixels.
    let norm = (cols * rows) as f32 / (width * height) as f32;
    CellLight {
        rows,
        cols,
        rgb: sums.into_iter().map(|s| s * norm).collect(),
    }
}

/// For each of `n` pixels along an axis, the cells of `cells` it falls in and
/// the length of pixel inside each.
fn overlaps(n: usize, cells: usize) -> Vec<Vec<(usize, f32)>> {
    let size = n as f64 / cells as f64;
    (0..n)
        .map(|p| {
            let (a, b) = (p as f64, p as f64 + 1.0);
            let first = ((a / size).floor() as usize).min(cells - 1);
            let last = (((b / size).ceil() as usize).max(1) - 1).min(cells - 1);
            (first..=last)
                .filter_map(|c| {
                    let inside = b.min((c + 1) as f64 * size) - a.max(c as f64 * size);
                    (inside > 1e-9).then_some((c, inside as f32))
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    fn uniform(v: f32) -> CellLight {
        CellLight::uniform(16, 32, Vec3::new(v, v, v))
    }

    fn mean_byte(img: &RgbImage) -> f64 {
        img.data.iter().map(|&b| b as f64).sum::<f64>() / img.data.len() as f64
    }

    fn small(settings: WebcamSettings) -> Webcam {
        Webcam::new(WebcamSettings {
            width: 64,
            height: 48,
            ..settings
        })
        .unwrap()
    }

    #[test]
    fn screen_light_matches_the_cell_average_and_cuts_pixels_by_area() {
        // A 64x32 frame (a multiple of the grid) agrees with the simulator's own box average.
        let frame = RgbImage {
            width: 64,
            height: 32,
            data: (0..64 * 32 * 3).map(|i| (i * 7 % 256) as u8).collect(),
        };
        let got = screen_light(64, 32, 16, 32, |x, y| frame.pixel(x, y));
        let want = CellLight::from_frame(&frame, 16, 32);
        for (a, b) in got.rgb.iter().zip(&want.rgb) {
            assert!((*a - *b).length() < 1e-5, "{a:?} {b:?}");
        }
        // 48 columns on 32 cells: column 0 white fills cell 0 and half of cell 1's 1.5 columns.
        let l = screen_light(
            48,
            16,
            16,
            32,
            |x, _| if x == 0 { [255; 3] } else { [0; 3] },
        );
        assert!((l.rgb[0].x - 1.0 / 1.5).abs() < 1e-5, "{:?}", l.rgb[0]);
        assert!(l.rgb[1].x.abs() < 1e-6);
        // A single pixel lights every cell.
        let l = screen_light(1, 1, 16, 32, |_, _| [255; 3]);
        assert!(l.rgb.iter().all(|v| (v.x - 1.0).abs() < 1e-5));
    }

    #[test]
    fn a_brighter_screen_lights_the_person_more_and_the_room_adds_light() {
        let cam = small(WebcamSettings::default());
        let dark = mean_byte(&cam.frame(1.0, 0, &uniform(0.05)));
        let bright = mean_byte(&cam.frame(1.0, 0, &uniform(0.9)));
        assert!(bright > dark + 20.0, "{dark} -> {bright}");
        let lit_room = small(WebcamSettings {
            room_light: 3.0,
            ..WebcamSettings::default()
        });
        let dark_in_lit_room = mean_byte(&lit_room.frame(1.0, 0, &uniform(0.05)));
        assert!(
            dark_in_lit_room > dark + 20.0,
            "{dark} -> {dark_in_lit_room}"
        );
    }

    #[test]
    fn frozen_motion_holds_the_pose_and_the_person_leaves_when_told() {
        let natural = small(WebcamSettings::default());
        assert_ne!(natural.state(0.0).pose, natural.state(5.0).pose);
        let frozen = small(WebcamSettings {
            motion: Motion::Frozen,
            away_after: Some(2.0),
            ..WebcamSettings::default()
        });
        assert_eq!(frozen.state(0.0), frozen.state(1.9));
        assert!(!frozen.state(2.0).pose.present);
        assert!(!frozen.state(100.0).pose.present);
    }

    #[test]
    fn bad_settings_are_refused() {
        for s in [
            WebcamSettings {
                room_light: -1.0,
                ..WebcamSettings::default()
            },
            WebcamSettings {
                width: 8,
                ..WebcamSettings::default()
            },
        ] {
            assert!(Webcam::new(s).is_err());
        }
    }
}
