//! Named, built-in target lights: monitor content a person would recognise as a
//! kind of light. Each preset is a picture on the screen (where it is bright, and
//! in what colour), written as linear RGB over the screen's area and reduced to
//! the contract's light grid by averaging over each cell.

use std::sync::OnceLock;

use gst::glib;

use crate::light::{LIGHT_COLS, LIGHT_ROWS, Light};

/// A built-in target light (`target-preset`).
#[derive(Debug, Eq, PartialEq, Hash, Clone, Copy, Default, glib::Enum)]
#[repr(u32)]
#[enum_type(name = "GstLsydRelightTargetPreset")]
pub enum Preset {
    /// No preset: the target comes from target-environment or target-location.
    #[default]
    #[enum_value(
        name = "None: as target-preset, use target-environment or target-location; as source-preset, predict the light",
        nick = "none"
    )]
    None = 0,
    #[enum_value(
        name = "Soft front: an even, neutral white screen",
        nick = "soft-front"
    )]
    SoftFront = 1,
    #[enum_value(
        name = "Warm key left: a warm light on the user's left",
        nick = "warm-key-left"
    )]
    WarmKeyLeft = 2,
    #[enum_value(
        name = "Cool key right: a cool light on the user's right",
        nick = "cool-key-right"
    )]
    CoolKeyRight = 3,
    #[enum_value(
        name = "Rim: bright strips at both side edges, dark centre",
        nick = "rim"
    )]
    Rim = 4,
    #[enum_value(name = "Sunset: a low orange sun under a dusky sky", nick = "sunset")]
    Sunset = 5,
    #[enum_value(name = "Office: cool ceiling panels above, dim below", nick = "office")]
    Office = 6,
    #[enum_value(
        name = "Overcast: a soft grey-blue sky, brighter above",
        nick = "overcast"
    )]
    Overcast = 7,
    #[enum_value(
        name = "Candle: a small warm flame low in a dark room",
        nick = "candle"
    )]
    Candle = 8,
    #[enum_value(name = "Neon: saturated magenta left, cyan right", nick = "neon")]
    Neon = 9,
}

/// Samples per cell side when averaging a preset's picture over a cell.
const CELL_SAMPLES: usize = 8;

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn mix(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    std::array::from_fn(|c| a[c] + (b[c] - a[c]) * t)
}

fn scale(a: [f32; 3], s: f32) -> [f32; 3] {
    a.map(|v| v * s)
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|c| a[c] + b[c])
}

/// A soft round spot: 1 at `(cx, cy)`, falling to 0 at `radius` (screen widths).
fn spot(x: f32, y: f32, cx: f32, cy: f32, radius: f32) -> f32 {
    // Screen coordinates are fractions of width and height; the screen is 2:1.
    let d = ((x - cx).powi(2) + ((y - cy) * 0.5).powi(2)).sqrt();
    1.0 - smoothstep(0.0, radius, d)
}

impl Preset {
    /// Every preset but `None`, in the enum's order.
    pub const ALL: [Preset; 9] = [
        Preset::SoftFront,
        Preset::WarmKeyLeft,
        Preset::CoolKeyRight,
        Preset::Rim,
        Preset::Sunset,
        Preset::Office,
        Preset::Overcast,
        Preset::Candle,
        Preset::Neon,
    ];

    /// The preset's short name (its enum nick), as the command line takes it.
    pub fn nick(self) -> &'static str {
        match self {
            Preset::None => "none",
            Preset::SoftFront => "soft-front",
            Preset::WarmKeyLeft => "warm-key-left",
            Preset::CoolKeyRight => "cool-key-right",
            Preset::Rim => "rim",
            Preset::Sunset => "sunset",
            Preset::Office => "office",
            Preset::Overcast => "overcast",
            Preset::Candle => "candle",
            Preset::Neon => "neon",
        }
    }

    pub fn from_nick(nick: &str) -> Option<Preset> {
        Preset::ALL.into_iter().find(|p| p.nick() == nick)
    }

    /// Linear RGB the screen shows at `(x, y)`: fractions of its width from the
    /// left edge as the user sees it, and of its height from the top.
    fn radiance(self, x: f32, y: f32) -> [f32; 3] {
        const WARM: [f32; 3] = [1.0, 0.62, 0.3];
        const COOL: [f32; 3] = [0.45, 0.65, 1.0];
        match self {
            Preset::None => [0.0; 3],
            Preset::SoftFront => {
                // A near-white page with a slight fall-off to the corners.
                let v = 1.0 - 0.15 * ((x - 0.5).powi(2) + (y - 0.5).powi(2)) * 4.0;
                scale([0.78, 0.76, 0.72], v)
            }
            Preset::WarmKeyLeft => {
                let key = 1.0 - smoothstep(0.2, 0.45, x);
                add(scale(WARM, key), scale([0.04, 0.04, 0.05], 1.0 - key))
            }
            Preset::CoolKeyRight => {
                let key = smoothstep(0.55, 0.8, x);
                add(scale(COOL, key), scale([0.04, 0.04, 0.04], 1.0 - key))
            }
            Preset::Rim => {
                let edge = 1.0 - smoothstep(0.04, 0.12, x.min(1.0 - x));
                add(scale([0.95, 0.95, 1.0], edge), [0.01, 0.01, 0.012])
            }
            Preset::Sunset => {
                let sky = mix(
                    [0.05, 0.06, 0.2],
                    [0.9, 0.35, 0.15],
                    smoothstep(0.1, 0.7, y),
                );
                let ground = [0.08, 0.04, 0.03];
                let below = smoothstep(0.68, 0.74, y);
                let sun = spot(x, y, 0.5, 0.66, 0.12);
                add(mix(sky, ground, below), scale([1.0, 0.7, 0.3], sun))
            }
            Preset::Office => {
                let panel = |cx: f32| spot(x, y, cx, 0.08, 0.14);
                let ceiling = (panel(0.2) + panel(0.5) + panel(0.8)).min(1.0);
                let wall = mix(
                    [0.3, 0.32, 0.33],
                    [0.12, 0.12, 0.12],
                    smoothstep(0.2, 1.0, y),
                );
                add(
                    scale([0.85, 0.92, 1.0], ceiling),
                    scale(wall, 1.0 - ceiling),
                )
            }
            Preset::Overcast => mix(
                [0.62, 0.66, 0.72],
                [0.28, 0.29, 0.3],
                smoothstep(0.0, 1.0, y),
            ),
            Preset::Candle => {
                let flame = spot(x, y, 0.5, 0.8, 0.05);
                let glow = spot(x, y, 0.5, 0.8, 0.35);
                add(
                    add(
                        scale([1.0, 0.6, 0.2], flame),
                        scale([0.25, 0.09, 0.02], glow),
                    ),
                    [0.004, 0.003, 0.003],
                )
            }
            Preset::Neon => {
                let right = smoothstep(0.42, 0.58, x);
                mix([0.85, 0.05, 0.7], [0.05, 0.8, 0.85], right)
            }
        }
    }

    /// The preset as a light: its picture averaged over each cell of the grid.
    /// Drawn once per process: `source-preset` asks for it every frame.
    pub fn light(self) -> Light {
        static LIGHTS: OnceLock<Vec<Light>> = OnceLock::new();
        let lights = LIGHTS.get_or_init(|| Preset::ALL.iter().map(|p| p.drawn()).collect());
        match Preset::ALL.iter().position(|&p| p == self) {
            Some(i) => lights[i].clone(),
            None => self.drawn(),
        }
    }

    fn drawn(self) -> Light {
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut out = vec![0f32; 3 * n];
        let inv = 1.0 / (CELL_SAMPLES * CELL_SAMPLES) as f32;
        for r in 0..LIGHT_ROWS {
            for c in 0..LIGHT_COLS {
                let mut sum = [0f32; 3];
                for sy in 0..CELL_SAMPLES {
                    for sx in 0..CELL_SAMPLES {
                        let x = (c as f32 + (sx as f32 + 0.5) / CELL_SAMPLES as f32)
                            / LIGHT_COLS as f32;
                        let y = (r as f32 + (sy as f32 + 0.5) / CELL_SAMPLES as f32)
                            / LIGHT_ROWS as f32;
                        sum = add(sum, self.radiance(x, y));
                    }
                }
                for (ch, s) in sum.iter().enumerate() {
                    out[ch * n + r * LIGHT_COLS + c] = (s * inv).clamp(0.0, 1.0);
                }
            }
        }
        Light(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Mean of channel `ch` over columns `cols` of every row.
    fn mean(light: &Light, ch: usize, cols: std::ops::Range<usize>) -> f32 {
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut s = 0.0;
        for r in 0..LIGHT_ROWS {
            for c in cols.clone() {
                s += light.0[ch * n + r * LIGHT_COLS + c];
            }
        }
        s / (LIGHT_ROWS * cols.len()) as f32
    }

    fn rows_mean(light: &Light, rows: std::ops::Range<usize>) -> f32 {
        let n = LIGHT_ROWS * LIGHT_COLS;
        let mut s = 0.0;
        for ch in 0..3 {
            for r in rows.clone() {
                for c in 0..LIGHT_COLS {
                    s += light.0[ch * n + r * LIGHT_COLS + c];
                }
            }
        }
        s / (3 * LIGHT_COLS * rows.len()) as f32
    }

    #[test]
    fn keys_are_bright_on_their_side_and_coloured_as_named() {
        let warm = Preset::WarmKeyLeft.light();
        assert!(mean(&warm, 0, 0..8) > 5.0 * mean(&warm, 0, 24..32));
        assert!(
            mean(&warm, 0, 0..8) > 2.0 * mean(&warm, 2, 0..8),
            "warm: red over blue"
        );
        let cool = Preset::CoolKeyRight.light();
        assert!(mean(&cool, 2, 24..32) > 5.0 * mean(&cool, 2, 0..8));
        assert!(
            mean(&cool, 2, 24..32) > 1.5 * mean(&cool, 0, 24..32),
            "cool: blue over red"
        );
    }

    #[test]
    fn rim_is_lit_at_the_edges_only_and_candle_is_dark_but_for_its_flame() {
        let rim = Preset::Rim.light();
        assert!(mean(&rim, 1, 0..2) > 0.8 && mean(&rim, 1, 30..32) > 0.8);
        assert!(mean(&rim, 1, 8..24) < 0.02);
        let candle = Preset::Candle.light();
        let total: f32 = candle.0.iter().sum::<f32>() / candle.0.len() as f32;
        assert!(total < 0.05, "a candle-lit room is dark: {total}");
        let n = LIGHT_ROWS * LIGHT_COLS;
        let brightest = (0..n)
            .max_by(|&a, &b| candle.0[a].total_cmp(&candle.0[b]))
            .unwrap();
        let (row, col) = (brightest / LIGHT_COLS, brightest % LIGHT_COLS);
        assert!(
            (11..14).contains(&row) && (14..18).contains(&col),
            "low centre: {row}, {col}"
        );
    }

    #[test]
    fn office_and_overcast_are_brighter_above_and_sunset_glows_low() {
        for p in [Preset::Office, Preset::Overcast] {
            let l = p.light();
            assert!(rows_mean(&l, 0..4) > 1.5 * rows_mean(&l, 12..16), "{p:?}");
        }
        let sunset = Preset::Sunset.light();
        assert!(
            mean(&sunset, 0, 14..18) > 2.0 * mean(&sunset, 2, 14..18),
            "orange"
        );
        assert!(rows_mean(&sunset, 9..12) > 2.0 * rows_mean(&sunset, 0..3));
    }

    #[test]
    fn every_preset_is_a_valid_distinct_light_with_a_name() {
        let lights: Vec<Light> = Preset::ALL.iter().map(|p| p.light()).collect();
        for (i, (p, l)) in Preset::ALL.iter().zip(&lights).enumerate() {
            assert!(l.0.iter().all(|v| (0.0..=1.0).contains(v)), "{p:?}");
            assert_eq!(Preset::from_nick(p.nick()), Some(*p));
            for other in &lights[i + 1..] {
                assert!(l.distance(other) > 0.03, "{p:?} looks like another preset");
            }
        }
        assert_eq!(Preset::from_nick("none"), None);
    }
}
