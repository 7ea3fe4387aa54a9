//! Surface appearance: albedo and specular lobe per part, from part parameters.
//!
//! Also the things that change between capture sessions of the same person:
//! the outfit and the room light.

use crate::math::{Vec3, gauss, smoothstep};
use crate::mesh::Part;
use crate::noise::{fbm2, value2};
use crate::rng::Rng;
use crate::subject::{EYE_ELEVATION_DEG, MOUTH_HALF_WIDTH_DEG, MOUTH_LINE_DEG, Subject};

/// Diffuse albedo (linear RGB) and a normalised Blinn–Phong lobe of exponent 2^`shine_log2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    pub albedo: Vec3,
    pub specular: f32,
    pub shine_log2: u8,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pattern {
    Solid,
    Stripes,
    Checks,
}

/// Clothing, which differs between captures (the paper's "outfits").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outfit {
    pub colour: Vec3,
    pub accent: Vec3,
    pub pattern: Pattern,
}

impl Outfit {
    pub fn random(r: &mut Rng) -> Outfit {
        let c = |r: &mut Rng| Vec3::new(r.range(0.02, 0.7), r.range(0.02, 0.7), r.range(0.02, 0.7));
        Outfit {
            colour: c(r),
            accent: c(r),
            pattern: match r.below(3) {
                0 => Pattern::Solid,
                1 => Pattern::Stripes,
                _ => Pattern::Checks,
            },
        }
    }
}

impl Default for Outfit {
    fn default() -> Self {
        Outfit {
            colour: Vec3::new(0.08, 0.14, 0.3),
            accent: Vec3::new(0.5, 0.5, 0.5),
            pattern: Pattern::Solid,
        }
    }
}

/// The room light that is on during a capture, besides the monitor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AmbientKind {
    /// An overhead light.
    Ceiling,
    /// A lamp on the subject's left (image right).
    LampLeft,
    /// A lamp on the subject's right (image left).
    LampRight,
    /// A window beside and a little in front of the subject.
    Window,
}

/// Room light: kind, colour and strength relative to a full-white monitor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ambient {
    pub kind: AmbientKind,
    /// Colour of the light (warm lamps, cool windows), about unit luminance.
    pub tint: Vec3,
    /// Irradiance at the face relative to a full-white monitor's. Below 1, as
    /// the paper requires: the room light never overpowers the monitor.
    pub ratio: f32,
}

pub const WARM: Vec3 = Vec3::new(1.25, 0.95, 0.65);
pub const NEUTRAL: Vec3 = Vec3::new(1.0, 1.0, 1.0);
pub const COOL: Vec3 = Vec3::new(0.85, 0.98, 1.2);

impl Ambient {
    pub fn random(r: &mut Rng) -> Ambient {
        let kind = match r.below(4) {
            0 => AmbientKind::Ceiling,
            1 => AmbientKind::LampLeft,
            2 => AmbientKind::LampRight,
            _ => AmbientKind::Window,
        };
        let tint = match kind {
            AmbientKind::Window => COOL,
            AmbientKind::Ceiling => [WARM, NEUTRAL, COOL][r.below(3)],
            _ => WARM,
        };
        Ambient {
            kind,
            tint,
            ratio: r.range(0.08, 0.35),
        }
    }

    /// Irradiance shape for a surface normal, at most 1.
    pub fn shape(&self, n: Vec3) -> f32 {
        let cos = |l: Vec3| n.dot(l.normalized()).max(0.0);
        match self.kind {
            AmbientKind::Ceiling => 0.25 + 0.75 * cos(Vec3::new(0.0, -1.0, -0.35)),
            AmbientKind::LampLeft => 0.15 + 0.85 * cos(Vec3::new(0.9, -0.35, -0.25)),
            AmbientKind::LampRight => 0.15 + 0.85 * cos(Vec3::new(-0.9, -0.35, -0.25)),
            AmbientKind::Window => 0.3 + 0.7 * cos(Vec3::new(-0.75, -0.2, -0.6)),
        }
    }
}

impl Default for Ambient {
    fn default() -> Self {
        Ambient {
            kind: AmbientKind::Ceiling,
            tint: NEUTRAL,
            ratio: 0.2,
        }
    }
}

/// What varies between capture sessions of one person.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Look {
    pub outfit: Outfit,
    pub ambient: Ambient,
}

impl Look {
    pub fn random(seed: u64, domain: &str) -> Look {
        let mut r = Rng::stream(seed, domain);
        Look {
            outfit: Outfit::random(&mut r),
            ambient: Ambient::random(&mut r),
        }
    }
}

fn skin(s: &Subject, th: f32, ph: f32) -> Surface {
    let seed = s.texture_seed;
    let aph = ph.abs();
    let blotch = fbm2(seed, ph / 9.0, th / 9.0, 3);
    let pores = value2(seed ^ 0x51, ph * 2.2, th * 2.2) - 0.5;
    let mut albedo = s.skin * (1.0 + 0.10 * blotch + 0.05 * pores);
    // Redness on the cheeks, nose tip and ears; shade around the eyes.
    let red = 0.7 * gauss(aph - 30.0, 9.0) * gauss(th + 12.0, 8.0)
        + 0.8 * gauss(ph, 4.0) * gauss(th + 12.0, 4.0);
    albedo = albedo.scale(Vec3::new(
        1.0 + 0.12 * red,
        1.0 - 0.08 * red,
        1.0 - 0.06 * red,
    ));
    let under_eye = gauss(aph - s.eye_spacing_deg, 9.0) * gauss(th - EYE_ELEVATION_DEG + 1.0, 5.0);
    albedo = albedo * (1.0 - 0.15 * under_eye);
    // The T-zone is oilier: stronger, tighter highlights.
    let t_zone = (gauss(ph, 6.0) * smoothstep(-16.0, -8.0, th))
        .max(gauss(th - 22.0, 8.0) * smoothstep(35.0, 20.0, aph));
    Surface {
        albedo,
        specular: s.skin_specular * (1.0 + 0.8 * t_zone),
        shine_log2: if t_zone > 0.5 { 5 } else { 4 },
    }
}

fn head(s: &Subject, th: f32, ph: f32) -> Surface {
    let aph = ph.abs();
    let mut surf = skin(s, th, ph);
    // Eyebrows: arched bands of hair above the eyes.
    let brow_th = 12.5 + 2.0 * (1.0 - ((aph - 24.0) / 14.0).powi(2)).max(0.0);
    let brow = smoothstep(1.8, 1.0, (th - brow_th).abs())
        * smoothstep(40.0, 36.0, aph)
        * smoothstep(7.0, 10.0, aph);
    if brow > 0.0 {
        let strands = 0.6 + 0.8 * value2(s.texture_seed ^ 0xB0, ph * 3.0, th * 0.7);
        surf.albedo = surf.albedo.lerp(s.brow * strands, brow * 0.9);
    }
    // Lash line along the eye opening.
    let open = s.eye_opening(th, ph, 0.0);
    let lash = 4.0 * open * (1.0 - open);
    surf.albedo = surf.albedo * (1.0 - 0.6 * lash);
    // Nostrils.
    let nostril = gauss(aph - 3.5 * s.nose_width, 1.3) * gauss(th + 16.0, 0.9);
    surf.albedo = surf.albedo * (1.0 - 0.85 * nostril.min(1.0));
    // Lips and the mouth between them.
    let in_mouth = smoothstep(MOUTH_HALF_WIDTH_DEG + 0.5, MOUTH_HALF_WIDTH_DEG - 1.5, aph);
    let lip_height = 1.0 - (aph / (MOUTH_HALF_WIDTH_DEG + 1.0)).powi(2);
    let upper = smoothstep(MOUTH_LINE_DEG + 0.4, MOUTH_LINE_DEG + 1.0, th)
        * smoothstep(
            MOUTH_LINE_DEG + 5.5 * lip_height + 0.5,
            MOUTH_LINE_DEG + 5.0 * lip_height,
            th,
        );
    let lower = smoothstep(MOUTH_LINE_DEG - 0.4, MOUTH_LINE_DEG - 1.0, th)
        * smoothstep(
            MOUTH_LINE_DEG - 6.0 * lip_height - 0.5,
            MOUTH_LINE_DEG - 5.5 * lip_height,
            th,
        );
    let lip = (upper + lower).min(1.0) * in_mouth;
    if lip > 0.0 {
        surf.albedo = surf.albedo.lerp(
            s.lip * (1.0 + 0.06 * (value2(s.texture_seed ^ 0x1B, ph * 4.0, th) - 0.5)),
            lip,
        );
        surf.specular *= 1.0 + lip;
        surf.shine_log2 = 5;
    }
    let cavity = smoothstep(0.6, 0.3, (th - MOUTH_LINE_DEG).abs()) * in_mouth;
    if cavity > 0.0 {
        surf.albedo = surf.albedo.lerp(Vec3::new(0.03, 0.008, 0.008), cavity);
        surf.specular *= 1.0 - cavity;
    }
    surf
}

fn eye(s: &Subject, angle_from_gaze: f32) -> Surface {
    let albedo = if angle_from_gaze < 7.0 {
        Vec3::new(0.01, 0.01, 0.01)
    } else if angle_from_gaze < 19.0 {
        s.iris * (0.7 + 0.6 * (angle_from_gaze - 7.0) / 12.0)
    } else {
        Vec3::new(0.62, 0.58, 0.55).lerp(
            Vec3::new(0.6, 0.35, 0.3),
            smoothstep(60.0, 90.0, angle_from_gaze),
        )
    };
    Surface {
        albedo,
        specular: 0.3,
        shine_log2: 8,
    }
}

fn cloth(o: &Outfit, u: f32, v: f32) -> Surface {
    let accent = match o.pattern {
        Pattern::Solid => false,
        Pattern::Stripes => (v * 0.5).rem_euclid(6.0) < 2.0,
        Pattern::Checks => {
            ((u / 20.0).floor() as i64 + (v / 8.0).floor() as i64).rem_euclid(2) == 0
        }
    };
    let weave = 1.0 + 0.08 * (value2(17, u * 3.0, v * 3.0) - 0.5);
    Surface {
        albedo: if accent { o.accent } else { o.colour } * weave,
        specular: 0.02,
        shine_log2: 3,
    }
}

/// Surface of a subject part at its parameters.
pub fn surface(s: &Subject, look: &Look, part: Part, uv: [f32; 2]) -> Surface {
    match part {
        Part::Head => head(s, uv[1], uv[0]),
        Part::Hair => {
            let strands = 0.65 + 0.7 * value2(s.texture_seed ^ 0x4A, uv[0] * 6.0, uv[1] * 0.8);
            Surface {
                albedo: s.hair * strands,
                specular: 0.025 * strands,
                shine_log2: 4,
            }
        }
        Part::EyeRight | Part::EyeLeft => eye(s, uv[1]),
        Part::Ear | Part::Neck => {
            let mut surf = skin(s, 0.0, 60.0);
            surf.albedo = surf.albedo * if part == Part::Ear { 0.97 } else { 0.9 };
            surf.specular *= 0.6;
            surf
        }
        Part::Torso => cloth(&look.outfit, uv[0], uv[1]),
    }
}

/// The room's back wall at camera-frame position (x, y): paint, a picture, a shelf, a door frame.
pub fn wall(x: f32, y: f32) -> Surface {
    let paint = Vec3::new(0.55, 0.52, 0.46) * (1.0 + 0.04 * fbm2(99, x * 8.0, y * 8.0, 3));
    let mut albedo = paint;
    if (0.32..0.78).contains(&x) && (-0.5..-0.12).contains(&y) {
        let inner = (0.35..0.75).contains(&x) && (-0.47..-0.15).contains(&y);
        albedo = if inner {
            Vec3::new(
                0.5 + 0.3 * fbm2(5, x * 6.0, y * 6.0, 3),
                0.3,
                0.2 + 0.2 * fbm2(6, x * 4.0, y * 4.0, 3),
            )
        } else {
            Vec3::new(0.08, 0.06, 0.04)
        };
    }
    if x < -0.35 && (0.05..0.09).contains(&y) {
        albedo = Vec3::new(0.3, 0.18, 0.09);
    }
    if (-0.95..-0.88).contains(&x) {
        albedo = Vec3::new(0.75, 0.74, 0.7);
    }
    Surface {
        albedo,
        specular: 0.0,
        shine_log2: 0,
    }
}
