//! Small fixed-size vector and matrix types for the renderer.
//!
//! Coordinates follow the camera convention used throughout the simulator:
//! x to the image right, y down, z forward (away from the camera), in metres.

use std::ops::{Add, AddAssign, Mul, Neg, Sub};

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec3 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}

impl Vec3 {
    pub const ZERO: Vec3 = Vec3::new(0.0, 0.0, 0.0);

    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }

    pub fn dot(self, o: Vec3) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    pub fn cross(self, o: Vec3) -> Vec3 {
        Vec3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }

    pub fn length(self) -> f32 {
        self.dot(self).sqrt()
    }

    /// Unit vector in the same direction; the zero vector stays zero.
    pub fn normalized(self) -> Vec3 {
        let len = self.length();
        if len > 0.0 { self * (1.0 / len) } else { self }
    }

    pub fn scale(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x * o.x, self.y * o.y, self.z * o.z)
    }

    pub fn lerp(self, o: Vec3, t: f32) -> Vec3 {
        self + (o - self) * t
    }

    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.z.is_finite()
    }
}

impl Add for Vec3 {
    type Output = Vec3;
    fn add(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl AddAssign for Vec3 {
    fn add_assign(&mut self, o: Vec3) {
        *self = *self + o;
    }
}

impl Sub for Vec3 {
    type Output = Vec3;
    fn sub(self, o: Vec3) -> Vec3 {
        Vec3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Mul<f32> for Vec3 {
    type Output = Vec3;
    fn mul(self, s: f32) -> Vec3 {
        Vec3::new(self.x * s, self.y * s, self.z * s)
    }
}

impl Neg for Vec3 {
    type Output = Vec3;
    fn neg(self) -> Vec3 {
        Vec3::new(-self.x, -self.y, -self.z)
    }
}

/// Row-major 3×3 matrix, used for rotations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mat3 {
    pub rows: [Vec3; 3],
}

impl Mat3 {
    pub const IDENTITY: Mat3 = Mat3 {
        rows: [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ],
    };

    /// Rotation about the x axis (pitch; positive tilts the face down in this frame).
    pub fn rot_x(a: f32) -> Mat3 {
        let (s, c) = a.sin_cos();
        Mat3 {
            rows: [
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, c, -s),
                Vec3::new(0.0, s, c),
            ],
        }
    }

    /// Rotation about the y axis (yaw).
    pub fn rot_y(a: f32) -> Mat3 {
        let (s, c) = a.sin_cos();
        Mat3 {
            rows: [
                Vec3::new(c, 0.0, s),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(-s, 0.0, c),
            ],
        }
    }

    /// Rotation about the z axis (roll).
    pub fn rot_z(a: f32) -> Mat3 {
        let (s, c) = a.sin_cos();
        Mat3 {
            rows: [
                Vec3::new(c, -s, 0.0),
                Vec3::new(s, c, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
        }
    }

    pub fn mul_vec(&self, v: Vec3) -> Vec3 {
        Vec3::new(
            self.rows[0].dot(v),
            self.rows[1].dot(v),
            self.rows[2].dot(v),
        )
    }

    pub fn mul_mat(&self, o: &Mat3) -> Mat3 {
        let col = |j: usize| match j {
            0 => Vec3::new(o.rows[0].x, o.rows[1].x, o.rows[2].x),
            1 => Vec3::new(o.rows[0].y, o.rows[1].y, o.rows[2].y),
            _ => Vec3::new(o.rows[0].z, o.rows[1].z, o.rows[2].z),
        };
        let row = |i: usize| {
            Vec3::new(
                self.rows[i].dot(col(0)),
                self.rows[i].dot(col(1)),
                self.rows[i].dot(col(2)),
            )
        };
        Mat3 {
            rows: [row(0), row(1), row(2)],
        }
    }

    /// Element-wise blend of two matrices; for the small angles of neck skinning
    /// this stays close enough to a rotation.
    pub fn lerp(&self, o: &Mat3, t: f32) -> Mat3 {
        Mat3 {
            rows: [
                self.rows[0].lerp(o.rows[0], t),
                self.rows[1].lerp(o.rows[1], t),
                self.rows[2].lerp(o.rows[2], t),
            ],
        }
    }
}

pub fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

pub fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// Unnormalised Gaussian bump exp(-(d/sigma)^2 / 2).
pub fn gauss(d: f32, sigma: f32) -> f32 {
    let t = d / sigma;
    (-0.5 * t * t).exp()
}
