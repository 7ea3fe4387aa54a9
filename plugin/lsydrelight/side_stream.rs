//! The `monitor_src` side stream: the predicted source light as a small RGB
//! video, one frame or GAP per face frame.
//!
//! It is driven by its own pad task fed from a short queue, so a sink that blocks
//! in preroll on one output never blocks the other. When the queue is full, a
//! non-live pipeline waits for the side branch (every frame arrives, at the pace
//! of the slower branch); a live one drops the oldest frame and says so once.

use std::collections::VecDeque;
use std::sync::atomic::Ordering;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Duration;

use gst::glib;
use gst::prelude::*;
use gst::subclass::prelude::*;
use gst_base::prelude::*;

use super::imp::{CAT, LsydRelight};
use crate::light::{LIGHT_COLS, LIGHT_ROWS, Light};

/// Size of the predicted-monitor video: each light cell becomes 8×8 pixels.
const MONITOR_SCALE: usize = 8;
/// Buffers queued for `monitor_src` before the element waits (non-live) or drops (live).
const QUEUE_BUFFERS: usize = 8;
/// How often a waiting push looks again, in case nothing wakes it.
const WAIT_SLICE: Duration = Duration::from_millis(100);

/// The side stream's caps at the face stream's frame rate.
pub fn caps(fps: gst::Fraction) -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(gst_video::VideoFormat::Rgb)
        .width((LIGHT_COLS * MONITOR_SCALE) as i32)
        .height((LIGHT_ROWS * MONITOR_SCALE) as i32)
        .framerate(fps)
        .pixel_aspect_ratio(gst::Fraction::new(1, 1))
        .build()
}

/// The pad template's caps: any frame rate.
pub fn template_caps() -> gst::Caps {
    gst_video::VideoCapsBuilder::new()
        .format(gst_video::VideoFormat::Rgb)
        .width((LIGHT_COLS * MONITOR_SCALE) as i32)
        .height((LIGHT_ROWS * MONITOR_SCALE) as i32)
        .framerate_range(gst::Fraction::new(0, 1)..=gst::Fraction::new(i32::MAX, 1))
        .pixel_aspect_ratio(gst::Fraction::new(1, 1))
        .build()
}

/// Items for `monitor_src`'s task, in order.
enum Item {
    Event(gst::Event),
    Buffer(gst::Buffer),
}

/// Whether a buffer made it into the queue.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Queued {
    Yes,
    /// The oldest queued buffer was dropped to make room (live pipelines).
    DroppedOldest,
    /// The stream is flushing: nothing is queued.
    Flushing,
}

#[derive(Default)]
struct Inner {
    items: VecDeque<Item>,
    flushing: bool,
    /// Stream-start, caps and segment have been queued.
    started: bool,
    /// The face stream's frame rate, for the caps query.
    fps: Option<gst::Fraction>,
    /// The face stream's id, from which the side stream's is derived (one cannot
    /// be made for an element with two sink pads).
    face_stream_id: Option<String>,
}

impl Item {
    /// A buffer or a GAP: what stands for one face frame.
    fn is_frame(&self) -> bool {
        match self {
            Item::Buffer(_) => true,
            Item::Event(e) => e.type_() == gst::EventType::Gap,
        }
    }
}

/// The queue between the aggregator's thread and `monitor_src`'s task.
#[derive(Default)]
pub struct SideStream {
    inner: Mutex<Inner>,
    cond: Condvar,
}

impl SideStream {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Sets the face stream's frame rate; true when it changed while the side
    /// stream runs, so new caps were queued.
    pub fn set_fps(&self, fps: gst::Fraction) -> bool {
        let mut q = self.lock();
        let changed = q.fps.replace(fps).is_some_and(|old| old != fps);
        if changed && q.started {
            q.items
                .push_back(Item::Event(gst::event::Caps::new(&caps(fps))));
            self.cond.notify_all();
        }
        changed
    }

    /// What the caps query answers: the caps at the face rate, once it is known.
    pub fn current_caps(&self) -> Option<gst::Caps> {
        self.lock().fps.filter(|f| f.numer() > 0).map(caps)
    }

    pub fn set_face_stream_id(&self, id: &str) {
        self.lock().face_stream_id = Some(id.to_owned());
    }

    /// Queues stream-start, caps and segment, once per stream.
    pub fn start(&self, segment: &gst::Segment) {
        let mut q = self.lock();
        if q.started {
            return;
        }
        let id = q
            .face_stream_id
            .as_deref()
            .map(|id| format!("{id}/monitor"))
            .unwrap_or_else(|| "lsydrelight/monitor".into());
        let fps = q.fps.unwrap_or(gst::Fraction::new(0, 1));
        q.items
            .push_back(Item::Event(gst::event::StreamStart::new(&id)));
        q.items
            .push_back(Item::Event(gst::event::Caps::new(&caps(fps))));
        // Before the face stream's own segment (an empty stream), a time segment from 0.
        let segment = match segment.format() {
            gst::Format::Time => segment.clone(),
            _ => gst::FormattedSegment::<gst::ClockTime>::new().upcast(),
        };
        q.items
            .push_back(Item::Event(gst::event::Segment::new(&segment)));
        q.started = true;
        self.cond.notify_all();
    }

    /// Queues an event once the stream has started (before that, stream-start,
    /// caps and segment carry the news).
    pub fn push_event(&self, event: gst::Event) {
        let mut q = self.lock();
        if q.flushing || !q.started {
            return;
        }
        q.items.push_back(Item::Event(event));
        self.cond.notify_all();
    }

    /// Queues what `monitor_src` shows for a face frame: the light as an image, or
    /// a GAP event for the frame's time when there is none. With a full queue,
    /// `wait` waits for room; otherwise the oldest buffer is dropped.
    pub fn push_frame(
        &self,
        light: Option<&Light>,
        pts: Option<gst::ClockTime>,
        duration: Option<gst::ClockTime>,
        wait: bool,
    ) -> Queued {
        let item = match light {
            Some(light) => {
                let mut buffer = gst::Buffer::from_mut_slice(light.to_rgb_image(MONITOR_SCALE));
                let b = buffer.get_mut().expect("a new buffer is writable");
                b.set_pts(pts);
                b.set_duration(duration);
                Item::Buffer(buffer)
            }
            None => match pts {
                Some(pts) => Item::Event(gst::event::Gap::builder(pts).duration(duration).build()),
                None => return Queued::Yes,
            },
        };
        let mut q = self.lock();
        let mut outcome = Queued::Yes;
        while !q.flushing && q.items.iter().filter(|i| i.is_frame()).count() >= QUEUE_BUFFERS {
            if wait {
                q = self
                    .cond
                    .wait_timeout(q, WAIT_SLICE)
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
                continue;
            }
            let oldest = q.items.iter().position(Item::is_frame);
            match oldest {
                Some(pos) => {
                    q.items.remove(pos);
                    outcome = Queued::DroppedOldest;
                }
                None => break,
            }
        }
        if q.flushing {
            return Queued::Flushing;
        }
        q.items.push_back(item);
        self.cond.notify_all();
        outcome
    }

    /// Queues the end of the side stream (starting it first if it never started).
    pub fn push_eos(&self, segment: &gst::Segment) {
        self.start(segment);
        let mut q = self.lock();
        if q.flushing {
            return;
        }
        q.items.push_back(Item::Event(gst::event::Eos::new()));
        self.cond.notify_all();
    }

    fn pop(&self) -> Option<Item> {
        let mut q = self.lock();
        loop {
            if q.flushing {
                return None;
            }
            if let Some(i) = q.items.pop_front() {
                self.cond.notify_all();
                return Some(i);
            }
            q = self.cond.wait(q).unwrap_or_else(|p| p.into_inner());
        }
    }

    /// While flushing, nothing is queued and every waiting push returns.
    pub fn set_flushing(&self, flushing: bool) {
        let mut q = self.lock();
        q.flushing = flushing;
        if flushing {
            q.items.clear();
        }
        self.cond.notify_all();
    }

    /// Forgets the stream: the next frame starts it again.
    pub fn reset(&self) {
        let mut q = self.lock();
        q.items.clear();
        q.started = false;
        self.cond.notify_all();
    }

    /// Forgets the stream and the face stream's rate and id, for a new run.
    pub fn clear(&self) {
        self.reset();
        let mut q = self.lock();
        q.fps = None;
        q.face_stream_id = None;
    }

    /// Starts or stops `pad`'s task, which pushes what is queued.
    pub fn activate(
        self: &std::sync::Arc<Self>,
        pad: &gst::Pad,
        active: bool,
    ) -> Result<(), glib::BoolError> {
        if !active {
            self.set_flushing(true);
            pad.stop_task()?;
            self.reset();
            return Ok(());
        }
        self.set_flushing(false);
        let side = self.clone();
        let task_pad = pad.clone();
        pad.start_task(move || match side.pop() {
            Some(Item::Event(e)) => {
                let eos = e.type_() == gst::EventType::Eos;
                task_pad.push_event(e);
                if eos {
                    let _ = task_pad.pause_task();
                }
            }
            Some(Item::Buffer(b)) => {
                // Not linked, flushing or EOS downstream: the side stream is optional,
                // so the main stream goes on; its frames are counted as sent.
                let _ = task_pad.push(b);
            }
            None => {
                let _ = task_pad.pause_task();
            }
        })
    }
}

impl LsydRelight {
    /// Queues the predicted light (or a gap) for `monitor_src` at the face frame's time.
    pub(super) fn show_prediction(&self, light: Option<&Light>, face: &gst::Buffer) {
        self.side.start(&self.face_pad.segment());
        // A non-live pipeline waits for a slow side branch rather than lose its frames.
        let wait = !self.qos.is_live();
        let queued = self
            .side
            .push_frame(light, face.pts(), face.duration(), wait);
        if light.is_some() {
            self.count(|st| {
                st.monitor_out += 1;
                if queued == Queued::DroppedOldest {
                    st.monitor_dropped += 1;
                }
            });
        }
        if queued == Queued::DroppedOldest {
            gst::debug!(
                CAT,
                imp = self,
                "monitor_src is behind: dropped its oldest frame"
            );
            if !self.side_drop_warned.swap(true, Ordering::Relaxed) {
                gst::element_imp_warning!(
                    self,
                    gst::StreamError::Failed,
                    ("monitor_src falls behind the live face stream: dropping its oldest frames"),
                    [
                        "The branch after monitor_src consumes slower than the face frame rate; give it a leaky queue or a faster sink. stats' monitor-dropped counts them."
                    ]
                );
            }
        }
    }

    /// Sends a gap on the face stream downstream, and to `monitor_src`. Before the
    /// first frame (or after a flush) downstream has no segment yet, and a gap may
    /// not precede it: that gap is dropped.
    pub(super) fn forward_gap(&self, gap: &gst::Buffer) {
        let src = self.obj().src_pad().clone();
        if let Some(pts) = gap.pts()
            && src.sticky_event::<gst::event::Segment>(0).is_some()
        {
            let event = || {
                gst::event::Gap::builder(pts)
                    .duration(gap.duration())
                    .build()
            };
            gst::debug!(CAT, imp = self, "gap at {pts} passed on");
            src.push_event(event());
            if self.monitor_src.is_linked() {
                self.side.push_event(event());
            }
        }
    }
}
