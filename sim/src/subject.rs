//! The synthetic person: shape, materials, pose and expression.
//!
//! The head is a radial surface over the sphere, in head-local coordinates
//! with the camera convention (x to the subject's left, which is image right
//! for an unmirrored webcam; y down; z away from the camera, so the face
//! looks towards −z). Facial structure is a sum of smooth bumps placed in
//! (elevation, azimuth) degrees, so every feature that casts a shadow (brow
//! ridge, eye sockets, nose, lips, chin, cheekbones) is explicit geometry.

use crate::math::{Mat3, Vec3, gauss, lerp, smoothstep};
use crate::rng::Rng;

/// Seed of the default subject, the one person the shipped model is trained for.
pub const DEFAULT_SUBJECT_SEED: u64 = 7;

/// Linear-light RGB albedo.
pub type Albedo = Vec3;

/// Shape and material parameters of one synthetic person.
#[derive(Clone, Debug, PartialEq)]
pub struct Subject {
    pub seed: u64,
    /// Head ellipsoid semi-axes in metres (x half width, y half height, z half depth).
    pub head_axes: Vec3,
    pub nose_length: f32,
    pub nose_width: f32,
    pub brow_depth: f32,
    pub cheekbone: f32,
    pub chin: f32,
    pub jaw_taper: f32,
    pub lip_fullness: f32,
    pub eye_spacing_deg: f32,
    pub skin: Albedo,
    pub lip: Albedo,
    pub hair: Albedo,
    pub brow: Albedo,
    pub iris: Albedo,
    /// Elevation of the frontal hairline in degrees.
    pub hairline_deg: f32,
    /// Lowest elevation the hair reaches at the back, in degrees.
    pub hair_back_deg: f32,
    pub hair_thickness: f32,
    pub skin_specular: f32,
    pub texture_seed: u64,
}

impl Default for Subject {
    fn default() -> Self {
        Subject {
            seed: DEFAULT_SUBJECT_SEED,
            head_axes: Vec3::new(0.076, 0.115, 0.098),
            nose_length: 1.0,
            nose_width: 1.0,
            brow_depth: 1.0,
            cheekbone: 1.0,
            chin: 1.0,
            jaw_taper: 0.2,
            lip_fullness: 1.0,
            eye_spacing_deg: 24.0,
            skin: Vec3::new(0.52, 0.33, 0.25),
            lip: Vec3::new(0.45, 0.17, 0.15),
            hair: Vec3::new(0.06, 0.035, 0.02),
            brow: Vec3::new(0.07, 0.045, 0.03),
            iris: Vec3::new(0.12, 0.07, 0.03),
            hairline_deg: 33.0,
            hair_back_deg: -40.0,
            hair_thickness: 0.014,
            skin_specular: 0.05,
            texture_seed: DEFAULT_SUBJECT_SEED.wrapping_mul(0x5851_F42D),
        }
    }
}

impl Subject {
    /// The default subject for seed [`DEFAULT_SUBJECT_SEED`], any other seed a new person.
    pub fn from_seed(seed: u64) -> Subject {
        if seed == DEFAULT_SUBJECT_SEED {
            return Subject::default();
        }
        let mut r = Rng::stream(seed, "subject");
        let tone = r.f32();
        // Skin tones from deep to light, in linear albedo.
        let skin = Vec3::new(0.16, 0.08, 0.05).lerp(Vec3::new(0.62, 0.43, 0.34), tone);
        let lip = skin.scale(Vec3::new(0.85, 0.55, 0.58));
        let hair_shade = r.range(0.02, 0.35);
        let hair = Vec3::new(hair_shade, hair_shade * 0.62, hair_shade * 0.38);
        Subject {
            seed,
            head_axes: Vec3::new(
                r.range(0.070, 0.080),
                r.range(0.108, 0.122),
                r.range(0.092, 0.104),
            ),
            nose_length: r.range(0.8, 1.2),
            nose_width: r.range(0.85, 1.25),
            brow_depth: r.range(0.7, 1.3),
            cheekbone: r.range(0.6, 1.4),
            chin: r.range(0.7, 1.3),
            jaw_taper: r.range(0.12, 0.26),
            lip_fullness: r.range(0.8, 1.3),
            eye_spacing_deg: r.range(22.5, 25.5),
            skin,
            lip,
            hair,
            brow: hair.scale(Vec3::new(1.2, 1.2, 1.2)),
            iris: Vec3::new(r.range(0.03, 0.15), r.range(0.03, 0.12), r.range(0.02, 0.1)),
            hairline_deg: r.range(28.0, 38.0),
            hair_back_deg: r.range(-55.0, -30.0),
            hair_thickness: r.range(0.008, 0.02),
            skin_specular: r.range(0.03, 0.08),
            texture_seed: r.next_u64(),
        }
    }
}

/// Facial expression, each in [0, 1].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Expression {
    pub mouth_open: f32,
    pub smile: f32,
    pub blink: f32,
}

/// Rigid head pose relative to the rest position, plus whether the person is in view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Rotation about the vertical axis in radians; positive turns the face to image right.
    pub yaw: f32,
    /// Rotation about the horizontal axis in radians; positive tilts the face up.
    pub pitch: f32,
    /// Rotation about the view axis in radians.
    pub roll: f32,
    /// Head translation in metres from the rest position: shifting in the chair,
    /// which the shoulders follow only partly.
    pub translation: Vec3,
    /// Where the whole person (head and shoulders) has moved from the desk, in
    /// metres: walking about the room, which the shoulders follow fully.
    pub body: Vec3,
    /// False when the person has walked out of the frame.
    pub present: bool,
}

impl Default for Pose {
    fn default() -> Self {
        Pose {
            yaw: 0.0,
            pitch: 0.0,
            roll: 0.0,
            translation: Vec3::ZERO,
            body: Vec3::ZERO,
            present: true,
        }
    }
}

impl Pose {
    pub fn rotation(&self) -> Mat3 {
        // The face looks towards −z, so a positive yaw (face to image right, +x)
        // is a negative rotation about y, and a positive pitch (face up, −y) is
        // a negative rotation about x in this y-down frame.
        Mat3::rot_z(self.roll)
            .mul_mat(&Mat3::rot_y(-self.yaw))
            .mul_mat(&Mat3::rot_x(-self.pitch))
    }
}

/// A person in a pose with an expression: everything that fixes the geometry of a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct State {
    pub pose: Pose,
    pub expression: Expression,
}

/// Unit direction for head-surface parameters (elevation `th`, azimuth `ph`, degrees).
pub fn direction(th: f32, ph: f32) -> Vec3 {
    let (st, ct) = th.to_radians().sin_cos();
    let (sp, cp) = ph.to_radians().sin_cos();
    Vec3::new(sp * ct, -st, -cp * ct)
}

/// Where the lips part, in degrees of elevation.
pub const MOUTH_LINE_DEG: f32 = -30.5;
/// Half-width of the mouth in degrees of azimuth.
pub const MOUTH_HALF_WIDTH_DEG: f32 = 13.0;
/// Elevation of the eye centres in degrees.
pub const EYE_ELEVATION_DEG: f32 = 3.5;
/// Half-size of the open eye in degrees (azimuth, elevation).
pub const EYE_HALF_SIZE_DEG: (f32, f32) = (8.5, 4.4);

impl Subject {
    /// Radius of the undeformed head with its facial features, for direction (th, ph).
    /// This is the costly part of the shape; meshes cache it per subject.
    pub fn radius(&self, th: f32, ph: f32) -> f32 {
        let d = direction(th, ph);
        let a = self.head_axes;
        let base = 1.0 / ((d.x / a.x).powi(2) + (d.y / a.y).powi(2) + (d.z / a.z).powi(2)).sqrt();
        let aph = ph.abs();
        let front = smoothstep(80.0, 50.0, aph);
        let eye_ph = self.eye_spacing_deg;

        let brow_ridge =
            0.005 * self.brow_depth * gauss(th - 13.0, 4.0) * smoothstep(40.0, 22.0, aph);
        let sockets = -0.008 * gauss(aph - eye_ph, 8.5) * gauss(th - EYE_ELEVATION_DEG, 6.0);

        // Nose: a ridge that grows from the bridge to the tip and drops under it.
        let nose_profile = lerp(0.003, 0.024 * self.nose_length, smoothstep(10.0, -12.5, th))
            * smoothstep(-19.0, -14.0, th)
            * smoothstep(14.0, 8.0, th).max(0.25 * smoothstep(16.0, 10.0, th));
        let nose_sigma = (3.2 + 3.0 * smoothstep(-2.0, -13.0, th)) * self.nose_width;
        let nose = nose_profile * gauss(ph, nose_sigma);
        let alae = 0.0065
            * self.nose_width
            * gauss(aph - 5.5 * self.nose_width, 2.8)
            * gauss(th + 13.5, 2.6);

        let cheekbones = 0.006 * self.cheekbone * gauss(aph - 38.0, 10.0) * gauss(th + 6.0, 8.0);
        let lip_mask = smoothstep(MOUTH_HALF_WIDTH_DEG + 1.0, MOUTH_HALF_WIDTH_DEG - 4.0, aph);
        let upper_lip = 0.0055 * self.lip_fullness * gauss(th + 27.5, 2.3) * lip_mask;
        let lower_lip = 0.006 * self.lip_fullness * gauss(th + 33.5, 2.5) * lip_mask;
        let lip_groove = -0.0015 * gauss(th - MOUTH_LINE_DEG, 0.8) * lip_mask;
        let chin = 0.008 * self.chin * gauss(th + 48.0, 6.0) * gauss(ph, 13.0);
        let philtrum = 0.002 * gauss(th + 21.0, 3.0) * gauss(ph, 5.0);

        base + front
            * (brow_ridge
                + sockets
                + nose
                + alae
                + cheekbones
                + upper_lip
                + lower_lip
                + lip_groove
                + chin
                + philtrum)
    }

    /// How far the eyelids are open at (th, ph): 1 inside the eye opening, 0 on the lids.
    pub fn eye_opening(&self, th: f32, ph: f32, blink: f32) -> f32 {
        let (hw, hh) = EYE_HALF_SIZE_DEG;
        let hh = hh * (1.0 - blink).max(0.0);
        if hh <= 0.0 {
            return 0.0;
        }
        let dx = (ph.abs() - self.eye_spacing_deg) / hw;
        // The upper lid arches more than the lower one.
        let dy = (th - EYE_ELEVATION_DEG) / if th > EYE_ELEVATION_DEG { hh } else { hh * 0.8 };
        let r = (dx * dx + dy * dy).sqrt();
        smoothstep(1.0, 0.75, r)
    }

    /// Weight of the jaw's rotation at (th, ph): 0 above the lips, 1 on the chin.
    fn jaw_weight(th: f32, ph: f32) -> f32 {
        let near_mouth = smoothstep(MOUTH_HALF_WIDTH_DEG + 8.0, MOUTH_HALF_WIDTH_DEG, ph.abs());
        let hi = lerp(-22.0, MOUTH_LINE_DEG + 0.6, near_mouth);
        let lo = lerp(-48.0, MOUTH_LINE_DEG - 0.6, near_mouth);
        smoothstep(hi, lo, th)
    }

    /// Head-local point of the head surface at (th, ph) under an expression.
    pub fn head_point(&self, th: f32, ph: f32, e: &Expression) -> Vec3 {
        self.deform(self.radius(th, ph), th, ph, e)
    }

    /// Head-local point at (th, ph) with undeformed radius `r`, under an expression.
    pub fn deform(&self, r: f32, th: f32, ph: f32, e: &Expression) -> Vec3 {
        let mut r = r;
        // The eye opening pushes the surface back behind the eyeball.
        r -= 0.016 * self.eye_opening(th, ph, e.blink);
        let d = direction(th, ph);
        let mut p = d * r;
        // Narrower lower face.
        let taper = 1.0 - self.jaw_taper * smoothstep(-8.0, -52.0, th);
        p.x *= taper;

        // Smile: mouth corners up and out, cheeks forward.
        if e.smile > 0.0 {
            let corner =
                gauss(ph.abs() - MOUTH_HALF_WIDTH_DEG, 5.0) * gauss(th - MOUTH_LINE_DEG, 4.0);
            p.y -= 0.004 * e.smile * corner;
            p.x += 0.003 * e.smile * corner * ph.signum();
            let cheek = gauss(ph.abs() - 26.0, 8.0) * gauss(th + 18.0, 6.0);
            p += d * (0.0025 * e.smile * cheek);
        }
        // Mouth: the jaw rotates down about an axis near the ears.
        if e.mouth_open > 0.0 {
            let w = Self::jaw_weight(th, ph);
            let pivot = Vec3::new(0.0, 0.015, 0.025);
            let rot = Mat3::rot_x((16.0f32).to_radians() * e.mouth_open * w);
            p = pivot + rot.mul_vec(p - pivot);
        }
        p
    }

    /// Hair thickness above the head surface at (th, ph); zero where there is no hair.
    pub fn hair_height(&self, th: f32, ph: f32) -> f32 {
        let aph = ph.abs();
        // Hairline: high on the forehead, down to the temples above the ears, low at the back.
        let front = self.hairline_deg - 6.0 * (aph / 50.0).min(1.0).powi(2);
        let side = lerp(front, 14.0, smoothstep(45.0, 80.0, aph));
        let above_ear = lerp(side, 12.0, smoothstep(80.0, 100.0, aph));
        let line = lerp(above_ear, self.hair_back_deg, smoothstep(100.0, 140.0, aph));
        let cover = smoothstep(line - 0.5, line + 4.0, th);
        let fringe = 0.4 + 0.6 * smoothstep(-1.0, 12.0, th - line);
        cover * fringe * self.hair_thickness
    }

    /// Local frame of the left (+1) or right (−1) eyeball: centre and radius.
    pub fn eyeball(&self, side: f32) -> (Vec3, f32) {
        let ph = side * self.eye_spacing_deg;
        // Measured from the closed lid: the open eye's recess must not move the eyeball.
        let closed = Expression {
            blink: 1.0,
            ..Expression::default()
        };
        let lid = self.head_point(EYE_ELEVATION_DEG, ph, &closed);
        let radius = 0.0118;
        let d = direction(EYE_ELEVATION_DEG, ph * 0.55);
        // The eyeball's front sits 1.5 mm behind the closed lid.
        (lid - d * (radius + 0.0015), radius)
    }
}

/// The 68 facial landmarks (iBUG 300-W order) as head-surface parameters (th, ph),
/// which move with expression. Index 0 is on the subject's right (image left).
pub fn landmark_params(s: &Subject, e: &Expression) -> Vec<(f32, f32)> {
    let mut k = Vec::with_capacity(68);
    // 0–16 jaw contour, from the right ear round the chin to the left ear.
    for i in 0..17 {
        let ph = -80.0 + 10.0 * i as f32;
        let t = 1.0 - (ph / 80.0).powi(2);
        k.push((-4.0 - 54.0 * t.max(0.0).powf(0.85), ph));
    }
    // 17–21 right brow, 22–26 left brow (outer to inner, then inner to outer).
    for i in 0..5 {
        let ph = -38.0 + 7.0 * i as f32;
        k.push((12.0 + 2.0 * (1.0 - ((ph + 24.0) / 14.0).powi(2)), ph));
    }
    for i in 0..5 {
        let ph = 10.0 + 7.0 * i as f32;
        k.push((12.0 + 2.0 * (1.0 - ((ph - 24.0) / 14.0).powi(2)), ph));
    }
    // 27–30 nose bridge, 31–35 nose base.
    for th in [9.0, 1.0, -6.0, -13.0] {
        k.push((th, 0.0));
    }
    for ph in [-7.0, -3.5, 0.0, 3.5, 7.0] {
        k.push((if ph == 0.0 { -17.0 } else { -15.8 }, ph * s.nose_width));
    }
    // 36–41 right eye, 42–47 left eye: outer corner, two upper lid points,
    // inner corner, two lower lid points (the iBUG ring order).
    let (hw, hh) = EYE_HALF_SIZE_DEG;
    let open = (1.0 - e.blink).max(0.0);
    for side in [-1.0f32, 1.0] {
        let c = side * s.eye_spacing_deg;
        let outer = c + side * hw;
        let inner = c - side * hw;
        let upper = EYE_ELEVATION_DEG + hh * open * 0.85;
        let lower = EYE_ELEVATION_DEG - hh * 0.8 * open * 0.85;
        let ring = if side < 0.0 {
            [
                (EYE_ELEVATION_DEG, outer),
                (upper, c - 0.4 * hw),
                (upper, c + 0.4 * hw),
                (EYE_ELEVATION_DEG, inner),
                (lower, c + 0.4 * hw),
                (lower, c - 0.4 * hw),
            ]
        } else {
            [
                (EYE_ELEVATION_DEG, inner),
                (upper, c - 0.4 * hw),
                (upper, c + 0.4 * hw),
                (EYE_ELEVATION_DEG, outer),
                (lower, c + 0.4 * hw),
                (lower, c - 0.4 * hw),
            ]
        };
        k.extend_from_slice(&ring);
    }
    // 48–59 outer lip contour, 60–67 inner lip contour.
    let mw = MOUTH_HALF_WIDTH_DEG;
    let m = MOUTH_LINE_DEG;
    let outer = [
        (m, -mw),
        (m + 3.5, -0.65 * mw),
        (m + 5.0, -0.25 * mw),
        (m + 4.5, 0.0),
        (m + 5.0, 0.25 * mw),
        (m + 3.5, 0.65 * mw),
        (m, mw),
        (m - 4.0, 0.65 * mw),
        (m - 5.5, 0.25 * mw),
        (m - 5.8, 0.0),
        (m - 5.5, -0.25 * mw),
        (m - 4.0, -0.65 * mw),
    ];
    k.extend_from_slice(&outer);
    let inner = [
        (m, -0.85 * mw),
        (m + 0.6, -0.3 * mw),
        (m + 0.6, 0.0),
        (m + 0.6, 0.3 * mw),
        (m, 0.85 * mw),
        (m - 0.6, 0.3 * mw),
        (m - 0.6, 0.0),
        (m - 0.6, -0.3 * mw),
    ];
    k.extend_from_slice(&inner);
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixty_eight_landmarks() {
        let s = Subject::default();
        assert_eq!(landmark_params(&s, &Expression::default()).len(), 68);
    }

    #[test]
    fn nose_tip_protrudes_beyond_cheeks() {
        let s = Subject::default();
        let e = Expression::default();
        let tip = s.head_point(-13.0, 0.0, &e);
        let cheek = s.head_point(-13.0, 30.0, &e);
        assert!(tip.z < cheek.z - 0.02, "tip {tip:?} cheek {cheek:?}");
    }

    #[test]
    fn blink_closes_the_eye_opening() {
        let s = Subject::default();
        assert!(s.eye_opening(EYE_ELEVATION_DEG, s.eye_spacing_deg, 0.0) > 0.99);
        assert_eq!(
            s.eye_opening(EYE_ELEVATION_DEG, s.eye_spacing_deg, 1.0),
            0.0
        );
    }

    #[test]
    fn open_mouth_lowers_the_chin_only() {
        let s = Subject::default();
        let closed = Expression::default();
        let open = Expression {
            mouth_open: 1.0,
            ..closed
        };
        let chin_closed = s.head_point(-48.0, 0.0, &closed);
        let chin_open = s.head_point(-48.0, 0.0, &open);
        assert!(chin_open.y > chin_closed.y + 0.01);
        let nose_closed = s.head_point(-13.0, 0.0, &closed);
        let nose_open = s.head_point(-13.0, 0.0, &open);
        assert!((nose_open - nose_closed).length() < 1e-6);
    }
}
