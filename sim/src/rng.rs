//! Deterministic random numbers.
//!
//! Everything random in the simulator is a pure function of a seed and a
//! counter, so output never depends on thread count or evaluation order.

/// SplitMix64 finaliser: a strong 64-bit mix used as a hash.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Hash of a seed and a sequence of integer keys.
pub fn hash(seed: u64, keys: &[u64]) -> u64 {
    keys.iter().fold(mix64(seed), |h, &k| mix64(h ^ k))
}

/// Stable 64-bit hash of a label, to derive independent streams by name.
pub fn label(name: &str) -> u64 {
    name.bytes().fold(0xCBF2_9CE4_8422_2325u64, |h, b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01B3)
    })
}

/// Uniform in [0, 1) from a 64-bit hash.
pub fn unit(h: u64) -> f32 {
    ((h >> 40) as f32) * (1.0 / (1u64 << 24) as f32)
}

/// A sequential generator for parameter sampling.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self { state: mix64(seed) }
    }

    /// An independent generator for a named sub-stream.
    pub fn stream(seed: u64, name: &str) -> Self {
        Self::new(hash(seed, &[label(name)]))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        unit(self.next_u64())
    }

    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f32()
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    pub fn chance(&mut self, p: f32) -> bool {
        self.f32() < p
    }

    /// Standard normal by Box–Muller.
    pub fn normal(&mut self) -> f32 {
        gaussian_pair(self.next_u64()).0
    }
}

/// Two independent standard normals from one hash (Box–Muller).
pub fn gaussian_pair(h: u64) -> (f32, f32) {
    let u1 = ((h >> 32) as f32 + 0.5) * (1.0 / 4_294_967_296.0);
    let u2 = ((h & 0xFFFF_FFFF) as f32 + 0.5) * (1.0 / 4_294_967_296.0);
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (std::f32::consts::TAU * u2).sin_cos();
    (r * c, r * s)
}
