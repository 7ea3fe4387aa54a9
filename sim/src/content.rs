//! Video-like monitor content: scenes, pans, fades, text pages, solid colours,
//! a bright patch moving across the screen, and views of environment maps.
//!
//! Content comes from named seed domains ("train", "heldout", "target", ...),
//! so held-out and target lights can never occur in training data.

use serde::{Deserialize, Serialize};

use crate::math::{Vec3, gauss, lerp, smoothstep};
use crate::monitor::{RgbImage, linear_to_srgb};
use crate::noise::fbm2;
use crate::rng::Rng;

/// Size of the monitor frames the simulator shows and records (16:9).
pub const FRAME_WIDTH: usize = 256;
pub const FRAME_HEIGHT: usize = 144;

/// One kind of content, with its parameters. Colours are sRGB in [0, 1].
#[derive(Clone, Debug, PartialEq)]
pub enum Clip {
    /// A landscape-like picture, optionally panning horizontally (screen widths per second).
    Scene {
        seed: u64,
        sky_top: Vec3,
        horizon: Vec3,
        ground: Vec3,
        horizon_v: f32,
        sun: (f32, f32, f32),
        brightness: f32,
        pan_speed: f32,
    },
    /// A page of text lines, light or dark mode, optionally scrolling (screens per second).
    Text {
        seed: u64,
        dark: bool,
        scroll_speed: f32,
    },
    /// One colour over the whole screen.
    Solid(Vec3),
    /// A bright rectangle moving across a black screen, from `from` to `to` (screen units).
    Patch {
        colour: Vec3,
        size: f32,
        from: (f32, f32),
        to: (f32, f32),
    },
    /// The front 180° of an environment map, tone-mapped to LDR, optionally turning (degrees per second).
    EnvMap {
        seed: u64,
        indoor: bool,
        exposure: f32,
        sun: (f32, f32),
        turn_speed: f32,
    },
}

/// A clip shown from `start` for `duration` seconds, faded in from the previous one.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    pub clip: Clip,
    pub start: f64,
    pub duration: f64,
    pub fade_in: f64,
}

/// How a playlist changes over time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Style {
    /// Everything, as when watching videos: cuts and fades every few seconds.
    Capture,
    /// One still picture for the whole time.
    Steady,
    /// Slow pans, turning environments and long fades.
    Slow,
    /// Hard scene cuts every half second to second and a half.
    Cuts,
    /// A light stage's: one bright area at a time anywhere on the screen (or
    /// a whole screen of colour, or an environment), held a second or two, so
    /// that a held pose sees light from many sides.
    Stage,
}

impl Style {
    /// The style a capture session may be given by name (`deskstage captures --content`).
    pub fn of_capture(name: &str) -> Result<Style, String> {
        match name {
            "capture" => Ok(Style::Capture),
            "stage" => Ok(Style::Stage),
            _ => Err(format!("--content {name}: one of capture or stage")),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Playlist {
    pub segments: Vec<Segment>,
}

fn colour(r: &mut Rng) -> Vec3 {
    Vec3::new(r.f32(), r.f32(), r.f32())
}

impl Clip {
    /// A random clip of any kind from a generator.
    pub fn random(r: &mut Rng) -> Clip {
        match r.below(10) {
            0..=3 => Clip::random_scene(r, 0.0),
            4 => Clip::Text {
                seed: r.next_u64(),
                dark: r.chance(0.4),
                scroll_speed: if r.chance(0.5) {
                    r.range(0.02, 0.1)
                } else {
                    0.0
                },
            },
            5 => Clip::Solid(if r.chance(0.3) {
                Vec3::new(1.0, 1.0, 1.0) * r.range(0.0, 1.0)
            } else {
                colour(r)
            }),
            6 => Clip::random_patch(r),
            _ => Clip::random_env(r, 0.0),
        }
    }

    pub fn random_scene(r: &mut Rng, pan_speed: f32) -> Clip {
        let dark = r.chance(0.25);
        Clip::Scene {
            seed: r.next_u64(),
            sky_top: colour(r),
            horizon: colour(r),
            ground: colour(r) * 0.7,
            horizon_v: r.range(0.3, 0.75),
            sun: (r.f32(), r.range(0.0, 0.5), r.range(0.03, 0.15)),
            brightness: if dark {
                r.range(0.08, 0.35)
            } else {
                r.range(0.6, 1.0)
            },
            pan_speed,
        }
    }

    pub fn random_patch(r: &mut Rng) -> Clip {
        let y = r.range(0.2, 0.8);
        let left_to_right = r.chance(0.5);
        let (a, b) = if left_to_right {
            (0.05, 0.95)
        } else {
            (0.95, 0.05)
        };
        Clip::Patch {
            colour: if r.chance(0.6) {
                Vec3::new(1.0, 1.0, 1.0)
            } else {
                colour(r)
            },
            size: r.range(0.12, 0.3),
            from: (a, y),
            to: (b, r.range(0.2, 0.8)),
        }
    }

    /// A still bright area anywhere on the screen: one light of a light stage.
    pub fn random_light(r: &mut Rng) -> Clip {
        let at = (r.range(0.05, 0.95), r.range(0.1, 0.9));
        Clip::Patch {
            colour: if r.chance(0.5) {
                Vec3::new(1.0, 1.0, 1.0)
            } else {
                colour(r)
            },
            size: r.range(0.15, 0.5),
            from: at,
            to: at,
        }
    }

    pub fn random_env(r: &mut Rng, turn_speed: f32) -> Clip {
        Clip::EnvMap {
            seed: r.next_u64(),
            indoor: r.chance(0.5),
            exposure: r.range(0.5, 1.2),
            sun: (r.range(-80.0, 80.0), r.range(5.0, 45.0)),
            turn_speed,
        }
    }

    /// The clip's colour at screen position (u, v) in [0, 1]², `t` seconds into the clip,
    /// where `progress` is t over the clip's duration.
    fn colour_at(&self, u: f32, v: f32, t: f32, progress: f32) -> Vec3 {
        match *self {
            Clip::Scene {
                seed,
                sky_top,
                horizon,
                ground,
                horizon_v,
                sun,
                brightness,
                pan_speed,
            } => {
                let u = u + pan_speed * t;
                let c = if v < horizon_v {
                    let s = sky_top.lerp(horizon, (v / horizon_v).powf(1.5));
                    let clouds = fbm2(seed, u * 6.0, v * 12.0, 4);
                    let du =
                        (u - sun.0).rem_euclid(3.0).min((sun.0 - u).rem_euclid(3.0)) * 16.0 / 9.0;
                    let sun_glow = gauss((du * du + (v - sun.1).powi(2)).sqrt(), sun.2);
                    s * (1.0 + 0.3 * clouds) + Vec3::new(1.0, 0.95, 0.8) * sun_glow
                } else {
                    let g = fbm2(seed ^ 0xA5, u * 10.0, (v - horizon_v) * 30.0, 4);
                    ground * (0.6 + g + 0.4 * ((v - horizon_v) / (1.0 - horizon_v)))
                };
                // Objects: soft blobs of their own colour.
                let mut r = Rng::new(seed);
                let mut c = c;
                for _ in 0..4 {
                    let (ox, oy, os) = (r.f32() * 3.0, r.range(0.3, 1.0), r.range(0.05, 0.2));
                    let oc = colour(&mut r);
                    let dx = ((u - ox).rem_euclid(3.0)).min((ox - u).rem_euclid(3.0)) * 16.0 / 9.0;
                    let m = smoothstep(os, os * 0.8, (dx * dx + (v - oy).powi(2)).sqrt());
                    c = c.lerp(oc, m);
                }
                c * brightness
            }
            Clip::Text {
                seed,
                dark,
                scroll_speed,
            } => {
                let (bg, fg) = if dark {
                    (Vec3::new(0.12, 0.12, 0.13), Vec3::new(0.85, 0.85, 0.82))
                } else {
                    (Vec3::new(0.97, 0.97, 0.96), Vec3::new(0.1, 0.1, 0.12))
                };
                let y = (v + scroll_speed * t) * 24.0;
                let line = y.floor();
                let in_line = y - line;
                let margin = !(0.08..=0.92).contains(&u);
                if margin || in_line > 0.55 {
                    return bg;
                }
                let mut r = Rng::new(seed ^ (line as i64 as u64).wrapping_mul(0x9E37));
                if r.chance(0.12) {
                    return bg; // paragraph break
                }
                let end = r.range(0.4, 0.92);
                if u > end {
                    return bg;
                }
                // Words: gaps at pseudo-random positions along the line.
                let word = ((u * 30.0 + r.f32() * 10.0).floor() as i64).rem_euclid(7);
                if word == 0 { bg } else { fg }
            }
            Clip::Solid(c) => c,
            Clip::Patch {
                colour,
                size,
                from,
                to,
            } => {
                let p = (lerp(from.0, to.0, progress), lerp(from.1, to.1, progress));
                let dx = (u - p.0).abs() * 16.0 / 9.0;
                let dy = (v - p.1).abs();
                if dx < size * 0.5 && dy < size * 0.5 {
                    colour
                } else {
                    Vec3::ZERO
                }
            }
            Clip::EnvMap {
                seed,
                indoor,
                exposure,
                sun,
                turn_speed,
            } => {
                // The screen shows the front 180° of the map horizontally and
                // the matching 101° vertically, as the paper projects its maps.
                let lon = (u - 0.5) * 180.0 + turn_speed * t;
                let lat = (0.5 - v) * 180.0 * 9.0 / 16.0;
                let hdr = env_radiance(seed, indoor, sun, lon, lat);
                let ldr = hdr * exposure;
                Vec3::new(
                    linear_to_srgb(ldr.x.min(1.0)),
                    linear_to_srgb(ldr.y.min(1.0)),
                    linear_to_srgb(ldr.z.min(1.0)),
                )
            }
        }
    }
}

/// Linear HDR radiance of a procedural environment in direction (lon, lat) degrees.
fn env_radiance(seed: u64, indoor: bool, sun: (f32, f32), lon: f32, lat: f32) -> Vec3 {
    let mut r = Rng::new(seed);
    if indoor {
        let wall = Vec3::new(r.range(0.15, 0.4), r.range(0.12, 0.35), r.range(0.1, 0.3));
        let floor = wall * 0.5;
        let mut c = if lat < -10.0 { floor } else { wall };
        c = c * (1.0 + 0.3 * fbm2(seed, lon / 20.0, lat / 20.0, 3));
        // Windows: bright cool rectangles; lamps: warm blobs.
        for _ in 0..2 {
            let (wl, wb, ww, wh) = (
                r.range(-150.0, 150.0),
                r.range(-5.0, 20.0),
                r.range(15.0, 40.0),
                r.range(15.0, 35.0),
            );
            let dl = ((lon - wl + 180.0).rem_euclid(360.0) - 180.0).abs();
            if dl < ww * 0.5 && lat > wb && lat < wb + wh {
                c = Vec3::new(2.5, 2.7, 3.0) * r.range(0.6, 1.4);
            }
        }
        let lamp = (r.range(-150.0, 150.0), r.range(10.0, 60.0));
        let dl = (lon - lamp.0 + 180.0).rem_euclid(360.0) - 180.0;
        let d = (dl * dl + (lat - lamp.1).powi(2)).sqrt();
        c + Vec3::new(6.0, 4.2, 2.2) * gauss(d, 6.0)
    } else {
        let zen = Vec3::new(0.25, 0.45, 0.9) * r.range(0.6, 1.4);
        let hor = Vec3::new(0.8, 0.85, 0.95) * r.range(0.7, 1.3);
        let ground = Vec3::new(0.25, 0.22, 0.15) * r.range(0.5, 1.5);
        let mut c = if lat >= 0.0 {
            hor.lerp(zen, (lat / 90.0).sqrt())
        } else {
            ground * (1.0 + 0.4 * fbm2(seed, lon / 8.0, lat / 4.0, 4))
        };
        let dl = (lon - sun.0 + 180.0).rem_euclid(360.0) - 180.0;
        let d = (dl * dl + (lat - sun.1).powi(2)).sqrt();
        c +=
            Vec3::new(30.0, 27.0, 22.0) * gauss(d, 3.0) + Vec3::new(1.5, 1.3, 1.0) * gauss(d, 15.0);
        c
    }
}

impl Playlist {
    /// A random playlist of `duration` seconds in a named seed domain.
    pub fn random(seed: u64, domain: &str, duration: f64, style: Style) -> Playlist {
        let mut r = Rng::stream(seed, domain);
        let mut segments = Vec::new();
        let mut t = 0.0;
        while t < duration {
            let (clip, len, fade) = match style {
                Style::Capture => {
                    let fade = if r.chance(0.3) {
                        r.range(0.3, 1.5) as f64
                    } else {
                        0.0
                    };
                    (Clip::random(&mut r), r.range(1.5, 6.0) as f64, fade)
                }
                Style::Steady => (Clip::random_scene(&mut r, 0.0), duration, 0.0),
                Style::Slow => {
                    let clip = if r.chance(0.5) {
                        let speed = r.range(0.03, 0.08);
                        Clip::random_scene(&mut r, speed)
                    } else {
                        let speed = r.range(4.0, 10.0);
                        Clip::random_env(&mut r, speed)
                    };
                    (clip, r.range(3.0, 5.0) as f64, r.range(1.5, 2.5) as f64)
                }
                Style::Stage => {
                    let clip = match r.below(5) {
                        0 => Clip::random_env(&mut r, 0.0),
                        1 => Clip::Solid(colour(&mut r)),
                        _ => Clip::random_light(&mut r),
                    };
                    (clip, r.range(1.0, 2.5) as f64, 0.0)
                }
                Style::Cuts => {
                    let clip = match r.below(3) {
                        0 => Clip::random_env(&mut r, 0.0),
                        1 => Clip::Solid(colour(&mut r)),
                        _ => Clip::random_scene(&mut r, 0.0),
                    };
                    (clip, r.range(0.4, 1.5) as f64, 0.0)
                }
            };
            let fade_in = if segments.is_empty() { 0.0 } else { fade };
            segments.push(Segment {
                clip,
                start: t,
                duration: len,
                fade_in,
            });
            t += len;
        }
        Playlist { segments }
    }

    /// A playlist that shows one clip for ever.
    pub fn still(clip: Clip) -> Playlist {
        Playlist {
            segments: vec![Segment {
                clip,
                start: 0.0,
                duration: f64::INFINITY,
                fade_in: 0.0,
            }],
        }
    }

    fn segment_at(&self, t: f64) -> usize {
        self.segments
            .iter()
            .rposition(|s| s.start <= t)
            .unwrap_or(0)
    }

    /// True when a cut (not a fade) happens between times `a` and `b`.
    pub fn cut_between(&self, a: f64, b: f64) -> bool {
        self.segments
            .iter()
            .any(|s| s.start > a && s.start <= b && s.fade_in == 0.0)
    }

    /// The frame on screen at time `t`.
    pub fn frame(&self, t: f64) -> RgbImage {
        let i = self.segment_at(t);
        let seg = &self.segments[i];
        let local = (t - seg.start).max(0.0);
        let mix = if seg.fade_in > 0.0 && local < seg.fade_in && i > 0 {
            Some((&self.segments[i - 1], (local / seg.fade_in) as f32))
        } else {
            None
        };
        let mut img = RgbImage::new(FRAME_WIDTH, FRAME_HEIGHT);
        let progress = |s: &Segment, tt: f64| {
            if s.duration.is_finite() {
                ((tt - s.start) / s.duration).clamp(0.0, 1.0) as f32
            } else {
                0.0
            }
        };
        for y in 0..FRAME_HEIGHT {
            for x in 0..FRAME_WIDTH {
                let u = (x as f32 + 0.5) / FRAME_WIDTH as f32;
                let v = (y as f32 + 0.5) / FRAME_HEIGHT as f32;
                let mut c = seg.clip.colour_at(u, v, local as f32, progress(seg, t));
                if let Some((prev, w)) = mix {
                    let pc = prev
                        .clip
                        .colour_at(u, v, (t - prev.start) as f32, progress(prev, t));
                    c = pc.lerp(c, w);
                }
                let i = (y * FRAME_WIDTH + x) * 3;
                img.data[i] = to_u8(c.x);
                img.data[i + 1] = to_u8(c.y);
                img.data[i + 2] = to_u8(c.z);
            }
        }
        img
    }
}

fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The nine monitor lights of the held-out test set; never produced in training.
pub fn heldout_clips(seed: u64) -> Vec<Clip> {
    let mut r = Rng::stream(seed, "heldout");
    let mut v = vec![
        Clip::random_env(&mut r, 0.0),
        Clip::random_env(&mut r, 0.0),
        Clip::Patch {
            colour: Vec3::new(1.0, 1.0, 1.0),
            size: 0.3,
            from: (0.1, 0.4),
            to: (0.1, 0.4),
        },
        Clip::Patch {
            colour: Vec3::new(1.0, 1.0, 1.0),
            size: 0.3,
            from: (0.9, 0.4),
            to: (0.9, 0.4),
        },
        Clip::Text {
            seed: r.next_u64(),
            dark: false,
            scroll_speed: 0.0,
        },
        Clip::Solid(Vec3::new(
            r.range(0.4, 1.0),
            r.range(0.2, 0.8),
            r.range(0.2, 1.0),
        )),
    ];
    for _ in 0..3 {
        v.push(Clip::random_scene(&mut r, 0.0));
    }
    v
}

/// The nine monitor lights of the validation set: the same kinds as the held-out
/// set's, from their own stream, with the bright patches elsewhere.
pub fn validation_clips(seed: u64) -> Vec<Clip> {
    let mut r = Rng::stream(seed, "validation");
    let patch = |x: f32, y: f32| Clip::Patch {
        colour: Vec3::new(1.0, 1.0, 1.0),
        size: 0.3,
        from: (x, y),
        to: (x, y),
    };
    let mut v = vec![
        Clip::random_env(&mut r, 0.0),
        Clip::random_env(&mut r, 0.0),
        patch(0.25, 0.3),
        patch(0.75, 0.6),
        Clip::Text {
            seed: r.next_u64(),
            dark: true,
            scroll_speed: 0.0,
        },
        Clip::Solid(Vec3::new(
            r.range(0.2, 0.9),
            r.range(0.4, 1.0),
            r.range(0.2, 0.8),
        )),
    ];
    for _ in 0..3 {
        v.push(Clip::random_scene(&mut r, 0.0));
    }
    v
}

/// Target lights that test recordings are relit to, with names for file names.
pub fn target_clips() -> Vec<(&'static str, Clip)> {
    let mut r = Rng::stream(1, "target");
    vec![
        (
            "studio",
            Clip::Text {
                seed: r.next_u64(),
                dark: false,
                scroll_speed: 0.0,
            },
        ),
        ("sunset", {
            let mut e = Clip::random_env(&mut r, 0.0);
            if let Clip::EnvMap {
                indoor,
                sun,
                exposure,
                ..
            } = &mut e
            {
                *indoor = false;
                *sun = (-55.0, 8.0);
                *exposure = 0.9;
            }
            e
        }),
        (
            "left-key",
            Clip::Patch {
                colour: Vec3::new(1.0, 0.92, 0.8),
                size: 0.35,
                from: (0.12, 0.35),
                to: (0.12, 0.35),
            },
        ),
    ]
}

/// Useful for content that should not depend on anything: a uniform frame.
pub fn solid_frame(c: Vec3) -> RgbImage {
    Playlist::still(Clip::Solid(c)).frame(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn playlists_are_deterministic_and_domains_differ() {
        let a = Playlist::random(3, "train", 20.0, Style::Capture);
        let b = Playlist::random(3, "train", 20.0, Style::Capture);
        let c = Playlist::random(3, "heldout", 20.0, Style::Capture);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(a.frame(7.3), b.frame(7.3));
    }

    #[test]
    fn patch_moves_across_screen() {
        let p = Playlist {
            segments: vec![Segment {
                clip: Clip::Patch {
                    colour: Vec3::new(1.0, 1.0, 1.0),
                    size: 0.2,
                    from: (0.1, 0.5),
                    to: (0.9, 0.5),
                },
                start: 0.0,
                duration: 2.0,
                fade_in: 0.0,
            }],
        };
        let centroid = |img: &RgbImage| {
            let (mut s, mut n) = (0.0, 0.0);
            for y in 0..img.height {
                for x in 0..img.width {
                    let v = img.pixel(x, y)[0] as f32;
                    s += v * x as f32;
                    n += v;
                }
            }
            s / n
        };
        assert!(centroid(&p.frame(0.0)) < 0.3 * FRAME_WIDTH as f32);
        assert!(centroid(&p.frame(2.0)) > 0.7 * FRAME_WIDTH as f32);
    }

    #[test]
    fn cuts_style_cuts_often() {
        let p = Playlist::random(1, "rec", 10.0, Style::Cuts);
        assert!(p.segments.len() >= 7);
        assert!(p.cut_between(0.0, 10.0));
    }

    #[test]
    fn a_light_stage_shows_single_lights_on_both_sides() {
        let p = Playlist::random(3, "stage", 30.0, Style::Stage);
        let lights: Vec<f32> = (p.segments.iter())
            .filter_map(|s| match s.clip {
                Clip::Patch { from, to, .. } if from == to => Some(from.0),
                _ => None,
            })
            .collect();
        assert!(lights.len() * 2 > p.segments.len(), "mostly single lights");
        assert!(
            lights.iter().any(|&x| x < 0.3) && lights.iter().any(|&x| x > 0.7),
            "{lights:?}"
        );
        // Held a second or more, cut from one to the next.
        assert!(
            p.segments
                .iter()
                .all(|s| s.duration >= 1.0 && s.fade_in == 0.0)
        );
    }
}
