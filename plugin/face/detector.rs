//! The face detector: MediaPipe's BlazeFace short-range through ONNX Runtime.
//!
//! `models/face/blazeface.onnx` (made, and checked against MediaPipe, by
//! `train/lsyd/face_detector.py`; its card is `models/face/README.md`) takes the
//! frame letterboxed to 128 × 128 and scores 896 SSD anchors. This module owns
//! the steps around it: the letterbox, the anchors, decoding boxes and
//! keypoints, weighted non-maximum suppression and the way back to frame pixels.
//! It is MediaPipe's `face_detection_short_range` configuration throughout.

use std::fmt;
use std::path::{Path, PathBuf};

use ort::environment::Environment;
use ort::session::Session;
use ort::value::{TensorRef, ValueType};

use super::search;
use super::{FaceBox, Square, sample_square};
use crate::engine::EngineError;
use crate::engine::runtime::{inference, session_builder};
use crate::frame::Frame;

/// Side of the network's square input.
pub const INPUT_SIZE: usize = 128;
/// Anchors the network scores.
pub const ANCHORS: usize = 896;
/// Lowest score of a face.
pub const MIN_SCORE: f32 = 0.5;
/// How much higher the other look must score to box a small face the look
/// that boxed it last did not (see [`Look`]).
const LOOK_HYSTERESIS: f32 = 0.1;
/// Boxes overlapping the best one by more than this IoU are merged into it.
pub const SUPPRESSION_IOU: f32 = 0.3;
/// Strides of the network's four anchor layers, in input pixels.
const STRIDES: [usize; 4] = [8, 16, 16, 16];
/// Values per anchor: box (x, y, w, h), then 6 keypoints (x, y).
const REGRESSORS: usize = 16;
/// How to make the model again, for error messages.
const REMAKE: &str = "make it with `cd train && python -m lsyd.face_detector --out ../models/face`";

/// Why the detector's model cannot be used.
#[derive(Clone, Debug, PartialEq)]
pub enum DetectorError {
    Missing(PathBuf),
    /// ONNX Runtime cannot load it: the file and its message.
    Unreadable(PathBuf, String),
    /// It is not BlazeFace short-range: the file and what differs.
    Mismatch(PathBuf, String),
}

impl fmt::Display for DetectorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DetectorError::Missing(p) => write!(
                f,
                "the face detector model {} does not exist; the checkout ships it as \
                 models/face/blazeface.onnx, or {REMAKE}",
                p.display()
            ),
            DetectorError::Unreadable(p, e) => write!(
                f,
                "the face detector model {} cannot be loaded ({e}); {REMAKE}",
                p.display()
            ),
            DetectorError::Mismatch(p, e) => write!(
                f,
                "the face detector model {} is not BlazeFace short-range: {e}; {REMAKE}",
                p.display()
            ),
        }
    }
}

impl std::error::Error for DetectorError {}

/// A face before suppression, in fractions of the letterboxed square.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    /// xmin, ymin, xmax, ymax.
    bounds: [f32; 4],
    keypoints: [[f32; 2]; 6],
    score: f32,
}

impl Candidate {
    fn iou(&self, other: &Candidate) -> f32 {
        let (a, b) = (self.bounds, other.bounds);
        let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
        let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
        let inter = w * h;
        let union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter;
        if union > 0.0 { inter / union } else { 0.0 }
    }
}

pub struct FaceDetector {
    session: Session,
    /// Anchor centres in fractions of the input, in the network's output order.
    anchors: Vec<[f32; 2]>,
    /// A small face found by the last detection, looked for round where it was
    /// when the whole frame shows none.
    last_small: Option<FaceBox>,
    /// The look that boxed it, which the next detection keeps unless the
    /// other scores [`LOOK_HYSTERESIS`] higher.
    last_look: Option<Look>,
    /// The last detection's face when it found one alone and small, and the
    /// look that boxed it: the next detections look only there, and at both
    /// looks every [`search::WHOLE_FRAME_EVERY`]-th time.
    alone_small: Option<(FaceBox, Look)>,
    /// Detections since the whole frame was looked at.
    since_whole_frame: u32,
    /// The tile of [`search::tiles`] the next scan starts at.
    next_tile: usize,
    /// What the last detection looked in, for the element's debug log.
    pub last_search: SearchStep,
}

/// Which look boxed a small face: the whole frame's letterbox, where it is
/// small, or the square round it, where it is a third of the input. Where the
/// face is small the whole frame's box is often coarse and poorly scored
/// (the portrait in 720p: 0.57), but not always: the film clip's face, 24
/// input pixels high there, scores 0.92-0.98 in the whole frame and
/// 0.79-0.93 round itself, its box steadier in the whole frame.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Look {
    WholeFrame,
    Closer,
}

/// Where one detection looked.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SearchStep {
    /// At the whole frame's letterbox: not where a lone small face boxed
    /// round itself is looked for there only, nor a second time where a lone
    /// face boxed by the whole frame was just lost in it.
    pub whole_frame: bool,
    /// Round a small face: the one the whole frame shows, or the one the
    /// detection before found.
    pub near: bool,
    /// Tiles of the scan (none when a face was found without them).
    pub tiles: usize,
    /// The largest small face found is boxed as the whole frame boxed it: it
    /// scored higher there than round itself (see [`Look`]).
    pub whole_frame_box: bool,
}

impl FaceDetector {
    /// Loads `path` (BlazeFace short-range as ONNX) on the CPU with `threads`
    /// threads and checks its inputs and outputs.
    pub fn new(
        env: &Environment,
        path: &Path,
        threads: usize,
    ) -> Result<FaceDetector, DetectorError> {
        if !path.is_file() {
            return Err(DetectorError::Missing(path.to_path_buf()));
        }
        let unreadable =
            |e: &dyn fmt::Display| DetectorError::Unreadable(path.to_path_buf(), e.to_string());
        let session = session_builder(env, threads)
            .and_then(|mut b| b.commit_from_file(path))
            .map_err(|e| unreadable(&e))?;
        check_session(&session).map_err(|e| DetectorError::Mismatch(path.to_path_buf(), e))?;
        Ok(FaceDetector {
            session,
            anchors: anchors(),
            last_small: None,
            last_look: None,
            alone_small: None,
            since_whole_frame: 0,
            next_tile: 0,
            last_search: SearchStep::default(),
        })
    }

    /// The faces in `frame`, the whole frame's best score first, in the
    /// frame's pixels. Faces too small for the whole frame are looked at as
    /// [`search`] says: again round themselves (the closer look's box replaces
    /// the whole frame's where it scores higher, see [`Look`]), round the small
    /// face found before when the whole frame shows none, and, when no face is
    /// found, in the next tiles of a scan. A small face found alone is looked
    /// for only in the look that boxed it, but for every
    /// [`search::WHOLE_FRAME_EVERY`]-th detection, which takes both looks
    /// again, the whole frame's for faces that came in.
    pub fn detect(&mut self, frame: &Frame) -> Result<Vec<FaceBox>, EngineError> {
        let (w, h) = (frame.width, frame.height);
        // The look a lone face was just lost in, not taken again.
        let mut lost_alone = None;
        if let Some((alone, look)) = self.alone_small
            && self.since_whole_frame < search::WHOLE_FRAME_EVERY - 1
        {
            let square = match look {
                Look::WholeFrame => search::letterbox(w, h),
                Look::Closer => search::around(&alone, w, h),
            };
            let faces = self.detect_in(frame, square)?;
            if !faces.is_empty() {
                self.since_whole_frame += 1;
                self.remember(&faces, |_| look, w, h);
                self.last_search = SearchStep {
                    whole_frame: look == Look::WholeFrame,
                    near: look == Look::Closer,
                    whole_frame_box: look == Look::WholeFrame,
                    ..SearchStep::default()
                };
                return Ok(faces);
            }
            lost_alone = Some(look);
        }
        self.since_whole_frame = 0;
        let whole_frame_again = lost_alone != Some(Look::WholeFrame);
        let mut faces = if whole_frame_again {
            self.detect_in(frame, search::letterbox(w, h))?
        } else {
            Vec::new()
        };
        let whole_frame = faces.clone();
        let mut step = SearchStep {
            whole_frame: whole_frame_again,
            ..SearchStep::default()
        };
        let mut small = small_faces(&faces, w, h);
        // The face followed, where the whole frame misses it; not again in the
        // square that just came back empty.
        if let Some(last) = self.last_small.filter(|_| lost_alone != Some(Look::Closer))
            && small.len() < search::NEAR_LOOKS
            && !faces.iter().any(|f| f.is_same_face(&last))
        {
            small.push(last);
        }
        self.look_closer(frame, &small, &mut faces, &mut step)?;
        if faces.is_empty() {
            let tiles = search::tiles(w, h);
            while faces.is_empty() && step.tiles < search::TILES_PER_SEARCH.min(tiles.len()) {
                let tile = tiles[self.next_tile % tiles.len()];
                self.next_tile = (self.next_tile + 1) % tiles.len();
                step.tiles += 1;
                faces = self.detect_in(frame, tile)?;
            }
            // A face a tile shows is boxed as coarsely as in the whole frame.
            let small = small_faces(&faces, w, h);
            self.look_closer(frame, &small, &mut faces, &mut step)?;
        }
        // A face that kept the whole frame's box was boxed better there.
        self.remember(
            &faces,
            |face| {
                if whole_frame.contains(face) {
                    Look::WholeFrame
                } else {
                    Look::Closer
                }
            },
            w,
            h,
        );
        self.last_search = SearchStep {
            whole_frame_box: self.last_look == Some(Look::WholeFrame),
            ..step
        };
        Ok(faces)
    }

    /// What the next detection looks round: the largest small face, and the
    /// face when it is small and alone, each with the look that boxed it
    /// (`look_of`).
    fn remember(
        &mut self,
        faces: &[FaceBox],
        look_of: impl Fn(&FaceBox) -> Look,
        width: usize,
        height: usize,
    ) {
        self.last_small = small_faces(faces, width, height).first().copied();
        self.last_look = self.last_small.as_ref().map(&look_of);
        self.alone_small = match faces {
            [face] if search::is_small(face, width, height) => Some((*face, look_of(face))),
            _ => None,
        };
    }

    /// Looks again round each of `small`, merging what it finds into `faces`.
    /// Round the closer look's box of the detection before where it is the
    /// same face and has not moved by half its height, so that a still face
    /// is looked at in the same square every time and keeps its box; round
    /// the face as found where it moved further. A square as large as the
    /// whole frame's letterbox would only look again at what it showed.
    fn look_closer(
        &mut self,
        frame: &Frame,
        small: &[FaceBox],
        faces: &mut Vec<FaceBox>,
        step: &mut SearchStep,
    ) -> Result<(), EngineError> {
        let (w, h) = (frame.width, frame.height);
        for face in small {
            let finer = self
                .last_small
                .filter(|last| (last.cx - face.cx).hypot(last.cy - face.cy) < 0.5 * last.height);
            let square = search::around(&finer.unwrap_or(*face), w, h);
            if square.side >= search::letterbox(w, h).side {
                continue;
            }
            step.near = true;
            let near = self.detect_in(frame, square)?;
            // The look that boxed the face followed keeps it on a near tie, so a
            // still face whose two looks score alike is not boxed by each in turn.
            let bias = match self.last_look.filter(|_| finer.is_some()) {
                Some(Look::Closer) => LOOK_HYSTERESIS,
                Some(Look::WholeFrame) => -LOOK_HYSTERESIS,
                None => 0.0,
            };
            replace_or_add(faces, near, bias, |f| search::is_small(f, w, h));
        }
        Ok(())
    }

    /// The faces in the whole frame's letterbox alone, as the detector found
    /// them before it looked for small ones (the benchmark's peer).
    pub fn detect_whole_frame(&mut self, frame: &Frame) -> Result<Vec<FaceBox>, EngineError> {
        self.detect_in(frame, search::letterbox(frame.width, frame.height))
    }

    /// The faces in `square` of `frame` (black outside the frame), shrunk to
    /// the network's input, in the frame's pixels.
    fn detect_in(&mut self, frame: &Frame, letterbox: Square) -> Result<Vec<FaceBox>, EngineError> {
        let rgb = sample_square(frame, letterbox, INPUT_SIZE);
        let n = INPUT_SIZE * INPUT_SIZE;
        let mut input = vec![0f32; 3 * n];
        for (i, px) in rgb.iter().enumerate() {
            for c in 0..3 {
                input[c * n + i] = px[c] * 2.0 - 1.0;
            }
        }
        let tensor = TensorRef::from_array_view(([1usize, 3, INPUT_SIZE, INPUT_SIZE], &input[..]))
            .map_err(inference)?;
        let outputs = self
            .session
            .run(ort::inputs!["input" => tensor])
            .map_err(inference)?;
        let values = |name: &str| {
            outputs[name]
                .try_extract_tensor::<f32>()
                .map(|(_, v)| v)
                .map_err(inference)
        };
        let candidates = decode(
            &self.anchors,
            values("regressors")?,
            values("classificators")?,
        );
        let corner = [
            letterbox.cx - letterbox.side / 2.0,
            letterbox.cy - letterbox.side / 2.0,
        ];
        Ok(suppress(candidates)
            .into_iter()
            .map(|c| to_frame(&c, letterbox.side, corner))
            .collect())
    }
}

/// The small faces among `faces`, the largest first, at most
/// [`search::NEAR_LOOKS`] of them.
fn small_faces(faces: &[FaceBox], width: usize, height: usize) -> Vec<FaceBox> {
    let mut small: Vec<FaceBox> = faces
        .iter()
        .filter(|f| search::is_small(f, width, height))
        .copied()
        .collect();
    small.sort_by(|a, b| b.height.total_cmp(&a.height));
    small.truncate(search::NEAR_LOOKS);
    small
}

/// The faces `found` by a closer look merged into `faces`: one that is the same
/// face as a small one already there replaces it where it scores as high or
/// higher, `bias` added to its score (the closer look's box is then the
/// finer), keeping its place in the order; one the same as a face not small,
/// which the whole frame boxes well and the square may cut, is left out; the
/// others are appended.
fn replace_or_add(
    faces: &mut Vec<FaceBox>,
    found: Vec<FaceBox>,
    bias: f32,
    small: impl Fn(&FaceBox) -> bool,
) {
    for face in found {
        match faces.iter_mut().find(|f| f.is_same_face(&face)) {
            Some(coarse) if small(coarse) && face.score + bias >= coarse.score => *coarse = face,
            Some(_) => {}
            None => faces.push(face),
        }
    }
}

/// The anchors scoring at least [`MIN_SCORE`], their boxes and keypoints in
/// fractions of the input square.
fn decode(anchors: &[[f32; 2]], regressors: &[f32], logits: &[f32]) -> Vec<Candidate> {
    let size = INPUT_SIZE as f32;
    let mut out = Vec::new();
    for (i, (&logit, anchor)) in logits.iter().zip(anchors).enumerate() {
        // MediaPipe clips the logit before the sigmoid.
        let score = 1.0 / (1.0 + (-logit.clamp(-100.0, 100.0)).exp());
        if score < MIN_SCORE {
            continue;
        }
        let r = &regressors[i * REGRESSORS..(i + 1) * REGRESSORS];
        let (cx, cy) = (anchor[0] + r[0] / size, anchor[1] + r[1] / size);
        let (hw, hh) = (r[2] / size / 2.0, r[3] / size / 2.0);
        let keypoints = std::array::from_fn(|k| {
            [
                anchor[0] + r[4 + 2 * k] / size,
                anchor[1] + r[5 + 2 * k] / size,
            ]
        });
        out.push(Candidate {
            bounds: [cx - hw, cy - hh, cx + hw, cy + hh],
            keypoints,
            score,
        });
    }
    out
}

/// The anchor centres of BlazeFace short-range, in fractions of the input, in the
/// network's output order.
///
/// MediaPipe's SSD anchors with strides 8, 16, 16, 16, aspect ratio 1 plus the
/// interpolated scale (2 anchors a layer) and fixed anchor size (all 1 × 1, so
/// only centres matter). Consecutive layers of one stride share a grid: a 16 × 16
/// grid with 2 anchors a cell, then an 8 × 8 grid with 6; grid by grid, row by
/// row, cell by cell.
fn anchors() -> Vec<[f32; 2]> {
    let mut out = Vec::with_capacity(ANCHORS);
    let mut layer = 0;
    while layer < STRIDES.len() {
        let stride = STRIDES[layer];
        let layers = STRIDES[layer..]
            .iter()
            .take_while(|&&s| s == stride)
            .count();
        let grid = INPUT_SIZE / stride;
        for y in 0..grid {
            for x in 0..grid {
                let centre = [
                    (x as f32 + 0.5) / grid as f32,
                    (y as f32 + 0.5) / grid as f32,
                ];
                out.extend(std::iter::repeat_n(centre, 2 * layers));
            }
        }
        layer += layers;
    }
    out
}

/// Weighted non-maximum suppression, as MediaPipe's: best first, every remaining
/// candidate overlapping it by more than [`SUPPRESSION_IOU`] joins it, and the
/// face is their score-weighted mean box and keypoints with the best one's score.
/// Averaging the overlapping anchors steadies the box from frame to frame.
fn suppress(mut candidates: Vec<Candidate>) -> Vec<Candidate> {
    candidates.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut faces = Vec::new();
    while let Some(best) = candidates.first().copied() {
        let (group, rest): (Vec<Candidate>, Vec<Candidate>) = candidates
            .into_iter()
            .partition(|c| best.iou(c) > SUPPRESSION_IOU);
        candidates = rest;
        let total: f32 = group.iter().map(|c| c.score).sum();
        let mut face = Candidate {
            bounds: [0.0; 4],
            keypoints: [[0.0; 2]; 6],
            score: best.score,
        };
        for c in &group {
            let w = c.score / total;
            for (m, v) in face.bounds.iter_mut().zip(c.bounds) {
                *m += w * v;
            }
            for (m, v) in face.keypoints.iter_mut().zip(c.keypoints) {
                m[0] += w * v[0];
                m[1] += w * v[1];
            }
        }
        faces.push(face);
    }
    faces
}

/// A face in fractions of the letterboxed square (of `side` frame pixels, its
/// top-left corner at `corner`) in frame pixels.
fn to_frame(c: &Candidate, side: f32, corner: [f32; 2]) -> FaceBox {
    let [x0, y0, x1, y1] = c.bounds;
    let px = |v: f32, axis: usize| corner[axis] + v * side;
    FaceBox {
        cx: px((x0 + x1) / 2.0, 0),
        cy: px((y0 + y1) / 2.0, 1),
        width: (x1 - x0) * side,
        height: (y1 - y0) * side,
        score: c.score,
        keypoints: c.keypoints.map(|[x, y]| [px(x, 0), px(y, 1)]),
    }
}

/// The session must be BlazeFace short-range's: `input` [1, 3, 128, 128],
/// `regressors` [1, 896, 16], `classificators` [1, 896, 1], all float32.
fn check_session(session: &Session) -> Result<(), String> {
    let describe = |o: &ort::value::Outlet| match o.dtype() {
        ValueType::Tensor { ty, shape, .. } => format!("{} {:?} {ty:?}", o.name(), shape.to_vec()),
        other => format!("{} {other:?}", o.name()),
    };
    let want_in = [format!(
        "input {:?} Float32",
        [1, 3, INPUT_SIZE, INPUT_SIZE]
    )];
    let want_out = [
        format!("regressors {:?} Float32", [1, ANCHORS, REGRESSORS]),
        format!("classificators {:?} Float32", [1, ANCHORS, 1]),
    ];
    for (kind, outlets, want) in [
        ("inputs", session.inputs(), &want_in[..]),
        ("outputs", session.outputs(), &want_out[..]),
    ] {
        let got: Vec<String> = outlets.iter().map(describe).collect();
        if got != want {
            return Err(format!("its {kind} are {got:?}, not {want:?}"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn there_are_896_anchors_on_two_grids() {
        let a = anchors();
        assert_eq!(a.len(), ANCHORS);
        // The 16 x 16 grid's first cell, twice; then the 8 x 8 grid's, six times.
        assert_eq!(a[0], [0.5 / 16.0, 0.5 / 16.0]);
        assert_eq!(a[1], a[0]);
        assert_eq!(a[2], [1.5 / 16.0, 0.5 / 16.0]);
        assert_eq!(a[512], [0.5 / 8.0, 0.5 / 8.0]);
        assert_eq!(a[517], a[512]);
        assert_eq!(a[518], [1.5 / 8.0, 0.5 / 8.0]);
        assert_eq!(a[ANCHORS - 1], [7.5 / 8.0, 7.5 / 8.0]);
    }

    fn candidate(x: f32, score: f32) -> Candidate {
        Candidate {
            bounds: [x, 0.2, x + 0.2, 0.4],
            keypoints: [[x + 0.1, 0.3]; 6],
            score,
        }
    }

    #[test]
    fn overlapping_candidates_merge_weighted_by_score_and_apart_ones_stay() {
        let faces = suppress(vec![
            candidate(0.1, 0.6),
            candidate(0.12, 0.9),
            candidate(0.7, 0.8),
        ]);
        assert_eq!(faces.len(), 2);
        // The best one's score; the box between the two, nearer the better one.
        assert_eq!(faces[0].score, 0.9);
        let x = (0.1 * 0.6 + 0.12 * 0.9) / 1.5;
        assert!((faces[0].bounds[0] - x).abs() < 1e-6);
        assert!((faces[0].keypoints[3][0] - (x + 0.1)).abs() < 1e-6);
        assert_eq!(faces[1].bounds[0], 0.7);
    }

    fn face_box(cx: f32, height: f32) -> FaceBox {
        FaceBox {
            cx,
            cy: 300.0,
            width: height,
            height,
            score: 0.9,
            keypoints: [[cx, 300.0]; 6],
        }
    }

    #[test]
    fn a_closer_look_replaces_a_small_faces_coarse_box_in_its_place_and_adds_new_faces() {
        // Small: under 150 px. The large face's box stays as the whole frame found it.
        let mut faces = vec![face_box(200.0, 180.0), face_box(900.0, 120.0)];
        replace_or_add(
            &mut faces,
            vec![
                face_box(210.0, 150.0),
                face_box(905.0, 100.0),
                face_box(1500.0, 60.0),
            ],
            0.0,
            |f| f.height < 150.0,
        );
        assert_eq!(
            faces,
            vec![
                face_box(200.0, 180.0),
                face_box(905.0, 100.0),
                face_box(1500.0, 60.0)
            ]
        );
        // A closer look that scores lower than the whole frame's box leaves it.
        let worse = FaceBox {
            score: 0.8,
            ..face_box(910.0, 110.0)
        };
        replace_or_add(&mut faces, vec![worse], 0.0, |f| f.height < 150.0);
        assert_eq!(faces[1], face_box(905.0, 100.0));
        // Unless the look that boxed it last was the closer one, by less than the hysteresis.
        let tie = FaceBox {
            score: 0.82,
            ..face_box(910.0, 110.0)
        };
        replace_or_add(&mut faces, vec![tie], LOOK_HYSTERESIS, |f| f.height < 150.0);
        assert_eq!(faces[1], tie);
    }

    #[test]
    fn the_largest_small_faces_are_looked_at_again() {
        // In a 1280 x 720 frame a face under 427 px (43 of 128 input px) is small.
        let faces = [
            face_box(100.0, 120.0),
            face_box(400.0, 500.0),
            face_box(700.0, 300.0),
            face_box(1000.0, 200.0),
        ];
        let small = small_faces(&faces, 1280, 720);
        assert_eq!(small, vec![face_box(700.0, 300.0), face_box(1000.0, 200.0)]);
    }

    #[test]
    fn letterbox_fractions_map_back_to_frame_pixels() {
        // A 640x360 frame's letterbox is 640 square, its corner at (0, -140).
        let f = to_frame(&candidate(0.25, 0.9), 640.0, [0.0, -140.0]);
        assert!((f.cx - 0.35 * 640.0).abs() < 1e-3);
        assert!((f.cy - (0.3 * 640.0 - 140.0)).abs() < 1e-3);
        assert!((f.width - 0.2 * 640.0).abs() < 1e-3 && (f.height - 0.2 * 640.0).abs() < 1e-3);
    }
}
