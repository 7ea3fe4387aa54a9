//! Triangle meshes of the posed subject.
//!
//! Every part is a grid surface over its own parameters. Each vertex keeps
//! its parameters (`uv`) so materials are evaluated per pixel from the
//! parameters rather than baked at mesh resolution.

use crate::math::{Mat3, Vec3, smoothstep};
use crate::subject::{EYE_ELEVATION_DEG, Expression, State, Subject, direction, landmark_params};

/// Which part of the person a triangle belongs to; selects the material.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Part {
    Head,
    Hair,
    EyeRight,
    EyeLeft,
    Ear,
    Neck,
    Torso,
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Vertex {
    pub pos: Vec3,
    pub normal: Vec3,
    /// Part parameters: (elevation, azimuth) in degrees for head and hair,
    /// angle from the gaze axis for eyes, surface coordinates elsewhere.
    pub uv: [f32; 2],
}

#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub vertices: Vec<Vertex>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_part: Vec<Part>,
}

/// Mesh resolution: angular step in degrees on the face and elsewhere.
#[derive(Clone, Copy, Debug)]
pub struct Detail {
    pub fine_deg: f32,
    pub coarse_deg: f32,
}

impl Detail {
    /// For the camera view: fine enough for eyelids and lip edges.
    pub const CAMERA: Detail = Detail {
        fine_deg: 0.75,
        coarse_deg: 3.0,
    };
    /// For shadow maps: only the shadow casters' shapes matter.
    pub const SHADOW: Detail = Detail {
        fine_deg: 3.0,
        coarse_deg: 8.0,
    };
}

/// Rest position of the head centre in the camera frame, metres.
pub const HEAD_REST: Vec3 = Vec3::new(0.0, 0.0, 0.62);
/// The head turns about this head-local point, at the top of the neck.
const NECK_PIVOT: Vec3 = Vec3::new(0.0, 0.07, 0.015);

/// Samples from `lo` to `hi` with step `fine` inside [`fine_lo`, `fine_hi`] and `coarse` outside.
fn steps(lo: f32, hi: f32, fine_lo: f32, fine_hi: f32, d: Detail) -> Vec<f32> {
    let mut v = vec![lo];
    let mut x = lo;
    while x < hi {
        let step = if x >= fine_lo - 1e-3 && x < fine_hi - 1e-3 {
            d.fine_deg
        } else {
            d.coarse_deg
        };
        // Land exactly on the fine band's edges.
        let next = if x < fine_lo - 1e-3 {
            (x + step).min(fine_lo)
        } else if x < fine_hi - 1e-3 {
            (x + step).min(fine_hi)
        } else {
            x + step
        };
        x = next.min(hi);
        v.push(x);
    }
    v
}

/// Rigid transform of the head and the blended one of the neck.
#[derive(Clone, Copy, Debug)]
pub struct Rig {
    rot: Mat3,
    head_origin: Vec3,
    torso_offset: Vec3,
}

impl Rig {
    pub fn new(state: &State) -> Rig {
        let t = state.pose.translation;
        let origin = HEAD_REST + state.pose.body;
        Rig {
            rot: state.pose.rotation(),
            head_origin: origin + t,
            // The torso follows the head's translation only partly.
            torso_offset: origin + t * 0.5,
        }
    }

    /// Head-local point to camera frame.
    pub fn head(&self, p: Vec3) -> Vec3 {
        self.head_origin + NECK_PIVOT + self.rot.mul_vec(p - NECK_PIVOT)
    }

    pub fn head_dir(&self, n: Vec3) -> Vec3 {
        self.rot.mul_vec(n)
    }

    fn torso(&self, p: Vec3) -> Vec3 {
        self.torso_offset + p
    }

    /// Neck vertices follow the head near it and the torso lower down.
    fn neck(&self, p: Vec3) -> Vec3 {
        let w = smoothstep(0.20, 0.07, p.y);
        let rot = Mat3::IDENTITY.lerp(&self.rot, w);
        let origin = self.torso_offset.lerp(self.head_origin, w);
        origin + NECK_PIVOT + rot.mul_vec(p - NECK_PIVOT)
    }
}

struct Builder<'a> {
    mesh: &'a mut Mesh,
}

impl Builder<'_> {
    /// Adds a grid surface; `keep(u, v)` drops cells whose four corners are all outside.
    /// Normals are made to point away from `inside`.
    #[allow(clippy::too_many_arguments)]
    fn grid(
        &mut self,
        part: Part,
        us: &[f32],
        vs: &[f32],
        wrap_u: bool,
        inside: Vec3,
        keep: impl Fn(usize) -> bool,
        pos: impl Fn(usize, f32, f32) -> Vec3,
    ) {
        let base = self.mesh.vertices.len() as u32;
        let first_tri = self.mesh.triangles.len();
        let nu = us.len();
        let nv = vs.len();
        let mut kept = Vec::with_capacity(nu * nv);
        for &v in vs {
            for &u in us {
                let k = kept.len();
                let keep = keep(k);
                self.mesh.vertices.push(Vertex {
                    // Vertices of dropped cells are never drawn; skip their cost.
                    pos: if keep { pos(k, u, v) } else { Vec3::ZERO },
                    normal: Vec3::ZERO,
                    uv: [u, v],
                });
                kept.push(keep);
            }
        }
        let cols = if wrap_u { nu } else { nu - 1 };
        for j in 0..nv - 1 {
            for i in 0..cols {
                let i1 = (i + 1) % nu;
                let a = j * nu + i;
                let b = j * nu + i1;
                let c = (j + 1) * nu + i;
                let d = (j + 1) * nu + i1;
                if !(kept[a] && kept[b] && kept[c] && kept[d]) {
                    continue;
                }
                let idx = |k: usize| base + k as u32;
                self.mesh.triangles.push([idx(a), idx(c), idx(b)]);
                self.mesh.triangles.push([idx(b), idx(c), idx(d)]);
                self.mesh.triangle_part.push(part);
                self.mesh.triangle_part.push(part);
            }
        }
        self.finish_normals(base as usize, first_tri, inside);
    }

    /// Area-weighted vertex normals for the part just added, oriented outwards.
    fn finish_normals(&mut self, first_vertex: usize, first_tri: usize, inside: Vec3) {
        let mesh = &mut *self.mesh;
        for t in &mesh.triangles[first_tri..] {
            let [a, b, c] = t.map(|k| k as usize);
            let n = (mesh.vertices[b].pos - mesh.vertices[a].pos)
                .cross(mesh.vertices[c].pos - mesh.vertices[a].pos);
            for k in [a, b, c] {
                mesh.vertices[k].normal += n;
            }
        }
        let mut outward = 0.0f64;
        for v in &mut mesh.vertices[first_vertex..] {
            v.normal = v.normal.normalized();
            outward += v.normal.dot(v.pos - inside) as f64;
        }
        if outward < 0.0 {
            for v in &mut mesh.vertices[first_vertex..] {
                v.normal = -v.normal;
            }
        }
    }
}

/// The pose-independent part of a subject's mesh at one level of detail:
/// the head's radius grid and the hair shell, which are costly to evaluate.
#[derive(Clone, Debug)]
pub struct Template {
    ths: Vec<f32>,
    phs: Vec<f32>,
    radius: Vec<f32>,
    /// Head-local hair points; None where there is no hair.
    hair: Vec<Option<Vec3>>,
    eye_pol: Vec<f32>,
    eye_azi: Vec<f32>,
}

impl Template {
    pub fn new(subject: &Subject, detail: Detail) -> Template {
        let ths = steps(-80.0, 90.0, -62.0, 42.0, detail);
        let mut phs = steps(-180.0, 180.0, -75.0, 75.0, detail);
        phs.pop(); // −180 and 180 coincide; the grid wraps instead.
        let mut radius = Vec::with_capacity(ths.len() * phs.len());
        let mut hair = Vec::with_capacity(ths.len() * phs.len());
        for &th in &ths {
            for &ph in &phs {
                let r = subject.radius(th, ph);
                radius.push(r);
                let h = subject.hair_height(th, ph);
                hair.push((h > 0.0008).then(|| {
                    let neutral = subject.deform(r, th, ph, &Expression::default());
                    neutral + direction(th, ph) * (h + 0.0004)
                }));
            }
        }
        let n = (180.0 / (detail.fine_deg * 6.0)).ceil() as usize;
        let eye_pol: Vec<f32> = (0..=n).map(|i| i as f32 * 180.0 / n as f32).collect();
        let eye_azi = (0..eye_pol.len() * 2)
            .map(|i| i as f32 * 360.0 / (eye_pol.len() * 2) as f32)
            .collect();
        Template {
            ths,
            phs,
            radius,
            hair,
            eye_pol,
            eye_azi,
        }
    }

    /// Builds the posed subject in the camera frame.
    pub fn build(&self, subject: &Subject, state: &State) -> Mesh {
        let mut mesh = Mesh::default();
        if !state.pose.present {
            return mesh;
        }
        let rig = Rig::new(state);
        let e = state.expression;
        let mut b = Builder { mesh: &mut mesh };
        let head_centre = rig.head(Vec3::ZERO);

        b.grid(
            Part::Head,
            &self.phs,
            &self.ths,
            true,
            head_centre,
            |_| true,
            |k, ph, th| rig.head(subject.deform(self.radius[k], th, ph, &e)),
        );
        // Hair: a shell over the cranium, cut at the hairline.
        b.grid(
            Part::Hair,
            &self.phs,
            &self.ths,
            true,
            head_centre,
            |k| self.hair[k].is_some(),
            |k, _, _| rig.head(self.hair[k].unwrap_or_default()),
        );

        // Eyes: spheres whose gaze follows the head.
        for (side, part) in [(-1.0f32, Part::EyeRight), (1.0, Part::EyeLeft)] {
            let (centre, radius) = subject.eyeball(side);
            let gaze = direction(EYE_ELEVATION_DEG - 3.0, side * 4.0);
            let (t1, t2) = orthonormal_basis(gaze);
            b.grid(
                part,
                &self.eye_azi,
                &self.eye_pol,
                true,
                rig.head(centre),
                |_| true,
                |_, az, po| {
                    let (sp, cp) = po.to_radians().sin_cos();
                    let (sa, ca) = az.to_radians().sin_cos();
                    rig.head(centre + (gaze * cp + t1 * (sp * ca) + t2 * (sp * sa)) * radius)
                },
            );
        }

        // Ears: cupped ovals on the sides of the head, facing out and a little forward.
        let around: Vec<f32> = (0..36).map(|i| i as f32 * 10.0).collect();
        let radial: Vec<f32> = (0..=8).map(|i| i as f32 / 8.0).collect();
        let a = subject.head_axes;
        for side in [-1.0f32, 1.0] {
            let centre = Vec3::new(side * (a.x + 0.004), 0.012, 0.016);
            let out = Vec3::new(side, 0.0, -0.35).normalized();
            let up = Vec3::new(0.0, -1.0, 0.0);
            let fwd = out.cross(up).normalized();
            b.grid(
                Part::Ear,
                &around,
                &radial,
                true,
                rig.head(Vec3::ZERO),
                |_| true,
                |_, ang, r| {
                    let (s, c) = ang.to_radians().sin_cos();
                    let bowl = -0.006 * (1.0 - r * r) + 0.004 * (-((r - 0.88) / 0.1).powi(2)).exp();
                    rig.head(
                        centre
                            + fwd * (0.016 * r * c)
                            + up * (0.030 * r * s)
                            + out * (0.010 + bowl),
                    )
                },
            );
        }

        // Neck: an elliptic cylinder from inside the head down into the torso.
        let neck_a: Vec<f32> = (0..48).map(|i| i as f32 * 7.5).collect();
        let neck_y: Vec<f32> = (0..=16).map(|i| 0.03 + 0.20 * i as f32 / 16.0).collect();
        b.grid(
            Part::Neck,
            &neck_a,
            &neck_y,
            true,
            rig.neck(Vec3::new(0.0, 0.12, 0.015)),
            |_| true,
            |_, ang, y| {
                let (s, c) = ang.to_radians().sin_cos();
                let flare = 1.0 + 0.25 * smoothstep(0.17, 0.23, y);
                rig.neck(Vec3::new(0.050 * flare * s, y, 0.015 + 0.055 * flare * c))
            },
        );

        // Torso: the upper half of a boxy superellipsoid: shoulders and chest.
        let tor_a: Vec<f32> = (0..72).map(|i| i as f32 * 5.0).collect();
        let tor_e: Vec<f32> = (0..=20).map(|i| -90.0 + 100.0 * i as f32 / 20.0).collect();
        b.grid(
            Part::Torso,
            &tor_a,
            &tor_e,
            true,
            rig.torso(TORSO_CENTRE),
            |_| true,
            |_, ang, el| {
                let (sa, ca) = ang.to_radians().sin_cos();
                let (se, ce) = el.to_radians().sin_cos();
                let sp = |x: f32| x.signum() * x.abs().powf(0.6);
                let p = Vec3::new(
                    0.22 * sp(ce) * sp(sa),
                    0.12 * sp(se),
                    0.11 * sp(ce) * sp(ca),
                );
                rig.torso(TORSO_CENTRE + p)
            },
        );
        mesh
    }
}

/// Centre of the torso relative to the head's rest position.
const TORSO_CENTRE: Vec3 = Vec3::new(0.0, 0.265, 0.04);

/// Two unit vectors orthogonal to `n` and to each other.
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let helper = if n.x.abs() < 0.9 {
        Vec3::new(1.0, 0.0, 0.0)
    } else {
        Vec3::new(0.0, 1.0, 0.0)
    };
    let t1 = n.cross(helper).normalized();
    (t1, n.cross(t1))
}

/// The 68 landmarks of a state in the camera frame (metres), or None when absent.
pub fn landmarks_3d(subject: &Subject, state: &State) -> Option<Vec<Vec3>> {
    if !state.pose.present {
        return None;
    }
    let rig = Rig::new(state);
    let e = state.expression;
    Some(
        landmark_params(subject, &e)
            .into_iter()
            .map(|(th, ph)| rig.head(subject.head_point(th, ph, &e)))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_cover_range_and_band() {
        let s = steps(
            -10.0,
            10.0,
            -2.0,
            2.0,
            Detail {
                fine_deg: 0.5,
                coarse_deg: 3.0,
            },
        );
        assert_eq!(*s.first().unwrap(), -10.0);
        assert_eq!(*s.last().unwrap(), 10.0);
        assert!(s.contains(&-2.0) && s.contains(&2.0));
        assert!(s.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn head_normals_point_outwards() {
        let s = Subject::default();
        let m = Template::new(&s, Detail::SHADOW).build(&s, &State::default());
        let centre = HEAD_REST;
        let mut outward = 0usize;
        let mut head = 0usize;
        for (t, part) in m.triangles.iter().zip(&m.triangle_part) {
            if *part == Part::Head {
                head += 1;
                let v = m.vertices[t[0] as usize];
                outward += (v.normal.dot(v.pos - centre) > 0.0) as usize;
            }
        }
        assert!(outward as f32 > 0.95 * head as f32, "{outward}/{head}");
    }

    #[test]
    fn absent_subject_has_no_mesh() {
        let mut st = State::default();
        st.pose.present = false;
        let s = Subject::default();
        assert!(
            Template::new(&s, Detail::SHADOW)
                .build(&s, &st)
                .triangles
                .is_empty()
        );
        assert!(landmarks_3d(&Subject::default(), &st).is_none());
    }
}
