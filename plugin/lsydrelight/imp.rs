//! The `lsydrelight` element's GObject and Aggregator glue: pads, start and
//! stop, events, queries and `aggregate`, which runs once per face frame.
//!
//! Each face frame takes its source light from the monitor stream
//! ([`super::monitor`], [`super::lights`]), goes through the per-frame policy
//! ([`crate::engine::policy`], [`super::process`]), gets the policy's lighting
//! change pasted on ([`super::video`]) and its predicted light shown on
//! `monitor_src` ([`super::side_stream`]). The face stream's state between
//! frames is [`super::state`]'s.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, LazyLock, Mutex};
use std::time::Instant;

use gst::glib;
use gst::prelude::*;
use gst::subclass::prelude::*;
use gst_base::prelude::*;
use gst_base::subclass::prelude::*;

use super::lock;
use super::match_check::MatchCheck;
use super::monitor::MonitorTrack;
use super::qos::{self, Qos};
use super::settings::{self, Settings};
use super::side_stream::{self, SideStream};
use super::state::State;
use super::stats::Stats;
use super::target::TargetSlot;
use super::video::{self, caps_advice, face_size_problem, is_gap, running_time};
use crate::frame::{DetailDenoiser, FrameCopy};
use crate::targets::Crossfade;

pub static CAT: LazyLock<gst::DebugCategory> = LazyLock::new(|| {
    gst::DebugCategory::new(
        "lsydrelight",
        gst::DebugColorFlags::empty(),
        Some("Personalised face relighting"),
    )
});

/// Reference-timestamp caps of the meta that names the monitor frame used.
pub static MONITOR_TIMESTAMP_CAPS: LazyLock<gst::Caps> =
    LazyLock::new(|| gst::Caps::new_empty_simple("timestamp/x-lsydrelight-monitor"));

pub struct LsydRelight {
    pub(super) face_pad: gst_base::AggregatorPad,
    pub(super) monitor_src: gst::Pad,
    monitor_pad: Mutex<Option<gst_base::AggregatorPad>>,
    /// The video target (`target_sink`), aligned like the monitor stream.
    pub(super) target_pad: Mutex<Option<gst_base::AggregatorPad>>,
    pub(super) target_track: Mutex<MonitorTrack>,
    pub(super) side: Arc<SideStream>,
    pub(super) settings: Mutex<Settings>,
    pub(super) target: Mutex<TargetSlot>,
    /// The inference lock: held while a frame is processed.
    pub(super) state: Mutex<Option<State>>,
    /// Kept after stop, so the last run's figures stay readable; reset at start.
    stats: Mutex<Stats>,
    pub(super) monitor: Mutex<MonitorTrack>,
    pub(super) qos: Qos,
    /// A warning about upstream's caps was posted (once per run).
    caps_warned: AtomicBool,
    /// A warning about dropped `monitor_src` frames was posted (once per run).
    pub(super) side_drop_warned: AtomicBool,
    pub(super) monitor_watch: Mutex<Option<gst::PeriodicClockId>>,
    pub(super) match_check: Mutex<MatchCheck>,
}

impl LsydRelight {
    /// The latency this element adds: the wait for monitor frames that lag the face
    /// (a negative `monitor-offset`) plus the time to relight a frame.
    fn report_latency(&self) {
        let (offset, processing) = {
            let s = lock(&self.settings);
            (s.monitor_offset, s.processing_latency)
        };
        let wait = gst::ClockTime::from_nseconds((-offset).max(0) as u64);
        gst::debug!(
            CAT,
            imp = self,
            "latency: monitor wait {wait}, processing {processing}"
        );
        self.obj().set_latency(wait + processing, None);
    }

    fn settings(&self) -> Settings {
        lock(&self.settings).clone()
    }

    pub(super) fn monitor_pad(&self) -> Option<gst_base::AggregatorPad> {
        lock(&self.monitor_pad).clone()
    }

    pub(super) fn count(&self, update: impl FnOnce(&mut Stats)) {
        update(&mut lock(&self.stats));
    }

    /// Applies GstController values (target-yaw and the like) at the face frame's stream time.
    fn sync_controlled(&self, face: &gst::Buffer) {
        let segment = self.face_pad.segment();
        let stream_time = segment
            .downcast_ref::<gst::ClockTime>()
            .and_then(|seg| seg.to_stream_time(face.pts()));
        if let Some(t) = stream_time
            && self.obj().has_active_control_bindings()
        {
            let _ = self.obj().sync_values(t);
        }
    }
}

#[glib::object_subclass]
impl ObjectSubclass for LsydRelight {
    const NAME: &'static str = "GstLsydRelight";
    type Type = super::LsydRelight;
    type ParentType = gst_base::Aggregator;

    fn with_class(klass: &Self::Class) -> Self {
        let face_pad = gst::PadBuilder::<gst_base::AggregatorPad>::from_template(
            &klass.pad_template("sink").unwrap(),
        )
        .name("sink")
        .build();
        let monitor_src =
            gst::Pad::builder_from_template(&klass.pad_template("monitor_src").unwrap())
                .name("monitor_src")
                .activatemode_function(|pad, parent, mode, active| {
                    LsydRelight::catch_panic_pad_function(
                        parent,
                        || {
                            Err(gst::loggable_error!(
                                CAT,
                                "panic while activating monitor_src"
                            ))
                        },
                        |imp| match mode {
                            gst::PadMode::Push => imp
                                .side
                                .activate(pad, active)
                                .map_err(|e| gst::loggable_error!(CAT, "monitor_src task: {e}")),
                            _ => Err(gst::loggable_error!(CAT, "monitor_src only pushes")),
                        },
                    )
                })
                .query_function(|pad, parent, query| {
                    LsydRelight::catch_panic_pad_function(
                        parent,
                        || false,
                        |imp| match query.view_mut() {
                            // Answered from the side stream, never waiting for a frame
                            // that is being relit.
                            gst::QueryViewMut::Caps(q) => {
                                let caps = imp
                                    .side
                                    .current_caps()
                                    .unwrap_or_else(|| pad.pad_template_caps());
                                let caps = match q.filter() {
                                    Some(f) => {
                                        f.intersect_with_mode(&caps, gst::CapsIntersectMode::First)
                                    }
                                    None => caps,
                                };
                                q.set_result(&caps);
                                true
                            }
                            _ => gst::Pad::query_default(pad, Some(&*imp.obj()), query),
                        },
                    )
                })
                .event_function(|_pad, _parent, event| {
                    // Upstream events on the side stream (QoS, navigation, reconfigure) have nowhere to go.
                    event.type_() == gst::EventType::Reconfigure
                })
                .build();
        Self {
            face_pad,
            monitor_src,
            monitor_pad: Mutex::new(None),
            target_pad: Mutex::new(None),
            target_track: Mutex::new(MonitorTrack::default()),
            side: Arc::new(SideStream::default()),
            settings: Mutex::new(Settings::default()),
            target: Mutex::new(TargetSlot::default()),
            state: Mutex::new(None),
            stats: Mutex::new(Stats::default()),
            monitor: Mutex::new(MonitorTrack::default()),
            qos: Qos::default(),
            caps_warned: AtomicBool::new(false),
            side_drop_warned: AtomicBool::new(false),
            monitor_watch: Mutex::new(None),
            match_check: Mutex::new(MatchCheck::default()),
        }
    }
}

impl ObjectImpl for LsydRelight {
    fn properties() -> &'static [glib::ParamSpec] {
        settings::properties()
    }

    fn set_property(&self, _id: usize, value: &glib::Value, pspec: &glib::ParamSpec) {
        match pspec.name() {
            name @ ("target-location" | "target-preset" | "target-environment" | "target-fov"
            | "target-yaw" | "target-pitch" | "target-exposure") => self.set_target(name, value),
            "monitor-offset" | "processing-latency" => {
                lock(&self.settings).set(pspec.name(), value);
                self.report_latency();
            }
            name => {
                let known = lock(&self.settings).set(name, value);
                debug_assert!(known, "property {name} is a setting");
            }
        }
    }

    fn property(&self, _id: usize, pspec: &glib::ParamSpec) -> glib::Value {
        match pspec.name() {
            "stats" => lock(&self.stats).to_structure().to_value(),
            name => lock(&self.settings)
                .get(name)
                .unwrap_or_else(|| panic!("property {name} is a setting")),
        }
    }

    fn constructed(&self) {
        self.parent_constructed();
        let obj = self.obj();
        obj.add_pad(&self.face_pad).expect("add sink pad");
        obj.add_pad(&self.monitor_src).expect("add monitor_src pad");
        self.report_latency();
    }

    fn dispose(&self) {
        self.stop_monitor_watch();
    }
}

impl GstObjectImpl for LsydRelight {}

impl ElementImpl for LsydRelight {
    fn metadata() -> Option<&'static gst::subclass::ElementMetadata> {
        static META: LazyLock<gst::subclass::ElementMetadata> = LazyLock::new(|| {
            gst::subclass::ElementMetadata::new(
                "Personalised face relighting",
                "Filter/Effect/Video",
                "Relights the face in a video to a target monitor light with a network personalised to the person, \
                 aligned with what their monitor showed (Choi, Christman, Sengupta, ECCV 2024)",
                "lsydrelight developers",
            )
        });
        Some(&*META)
    }

    fn pad_templates() -> &'static [gst::PadTemplate] {
        static TEMPLATES: LazyLock<Vec<gst::PadTemplate>> = LazyLock::new(|| {
            let agg = gst_base::AggregatorPad::static_type();
            let face = video::face_caps();
            vec![
                gst::PadTemplate::with_gtype(
                    "sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Always,
                    &face,
                    agg,
                )
                .expect("sink template"),
                gst::PadTemplate::with_gtype(
                    "monitor_sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Request,
                    &video::monitor_caps(),
                    agg,
                )
                .expect("monitor_sink template"),
                gst::PadTemplate::with_gtype(
                    "target_sink",
                    gst::PadDirection::Sink,
                    gst::PadPresence::Request,
                    &video::monitor_caps(),
                    agg,
                )
                .expect("target_sink template"),
                gst::PadTemplate::with_gtype(
                    "src",
                    gst::PadDirection::Src,
                    gst::PadPresence::Always,
                    &face,
                    agg,
                )
                .expect("src template"),
                gst::PadTemplate::new(
                    "monitor_src",
                    gst::PadDirection::Src,
                    gst::PadPresence::Always,
                    &side_stream::template_caps(),
                )
                .expect("monitor_src template"),
            ]
        });
        TEMPLATES.as_ref()
    }

    fn release_pad(&self, pad: &gst::Pad) {
        let mut tp = lock(&self.target_pad);
        if tp
            .as_ref()
            .is_some_and(|p| p.upcast_ref::<gst::Pad>() == pad)
        {
            *tp = None;
            drop(tp);
            *lock(&self.target_track) = MonitorTrack::default();
            gst::debug!(CAT, imp = self, "target_sink released");
            self.parent_release_pad(pad);
            return;
        }
        drop(tp);
        let mut mp = lock(&self.monitor_pad);
        if mp
            .as_ref()
            .is_some_and(|p| p.upcast_ref::<gst::Pad>() == pad)
        {
            *mp = None;
            drop(mp);
            *lock(&self.monitor) = MonitorTrack::default();
            gst::debug!(CAT, imp = self, "monitor_sink released");
        } else {
            drop(mp);
        }
        self.parent_release_pad(pad);
    }
}

impl AggregatorImpl for LsydRelight {
    fn start(&self) -> Result<(), gst::ErrorMessage> {
        let settings = self.settings();
        let (mut policy, region) = self.start_engine(&settings)?;
        let (target, target_generation) =
            TargetSlot::start(&self.target, &settings.target_source()).map_err(|e| {
                gst::error_msg!(
                    gst::ResourceError::NotFound,
                    ["{}; set target-location to a PNG image of monitor content (shipped ones are in models/targets), target-environment to a panorama, or target-preset", e]
                )
            })?;
        policy.set_target(&target).map_err(|e| {
            gst::error_msg!(
                gst::LibraryError::Failed,
                ["cannot encode the target light: {}", e]
            )
        })?;
        let mut fade = Crossfade::default();
        fade.jump((*target).clone());
        *lock(&self.state) = Some(State {
            policy,
            region,
            face_info: None,
            last_face_rt: None,
            target_generation,
            fade,
            nan_warned: false,
            denoiser: DetailDenoiser::default(),
            undenoised: FrameCopy::default(),
        });
        *lock(&self.stats) = Stats::default();
        lock(&self.monitor).restart();
        lock(&self.target_track).restart();
        self.caps_warned.store(false, Ordering::Relaxed);
        self.side_drop_warned.store(false, Ordering::Relaxed);
        self.start_monitor_watch();
        Ok(())
    }

    fn stop(&self) -> Result<(), gst::ErrorMessage> {
        self.stop_monitor_watch();
        lock(&self.target).stop();
        self.qos.reset();
        *lock(&self.state) = None;
        lock(&self.monitor).stop();
        lock(&self.target_track).stop();
        self.side.clear();
        Ok(())
    }

    fn src_activate(&self, mode: gst::PadMode, active: bool) -> Result<(), gst::LoggableError> {
        if !active {
            // The aggregating thread may wait for room on monitor_src; stopping the
            // src pad's task waits for that thread.
            self.side.set_flushing(true);
        }
        self.parent_src_activate(mode, active)
    }

    fn create_new_pad(
        &self,
        templ: &gst::PadTemplate,
        _req_name: Option<&str>,
        _caps: Option<&gst::Caps>,
    ) -> Option<gst_base::AggregatorPad> {
        let name = templ.name_template();
        let (slot, track) = match name {
            "monitor_sink" => (&self.monitor_pad, &self.monitor),
            "target_sink" => (&self.target_pad, &self.target_track),
            _ => return None,
        };
        let mut held = lock(slot);
        if held.is_some() {
            gst::warning!(CAT, imp = self, "only one {name} pad");
            return None;
        }
        let pad = gst::PadBuilder::<gst_base::AggregatorPad>::from_template(templ)
            .name(name)
            .build();
        *held = Some(pad.clone());
        drop(held);
        lock(track).attach(&pad);
        gst::debug!(CAT, imp = self, "{name} requested");
        Some(pad)
    }

    fn sink_event(&self, pad: &gst_base::AggregatorPad, event: gst::Event) -> bool {
        use gst::EventView;
        let is_face = pad == &self.face_pad;
        match event.view() {
            EventView::StreamStart(e) if is_face => {
                self.side.set_face_stream_id(e.stream_id());
                self.reset_state("new stream");
            }
            EventView::Caps(c) => {
                let Ok(info) = gst_video::VideoInfo::from_caps(c.caps()) else {
                    gst::element_imp_error!(
                        self,
                        gst::StreamError::Format,
                        ("Cannot read the caps {}", c.caps()),
                        ["{}", caps_advice(pad.name().as_str())]
                    );
                    return false;
                };
                if !is_face {
                    gst::debug!(CAT, imp = self, "{} caps {}", pad.name(), c.caps());
                    lock(self.track_of(pad)).set_info(info);
                    return self.parent_sink_event(pad, event);
                }
                if let Some(problem) = face_size_problem(&info) {
                    gst::element_imp_error!(
                        self,
                        gst::StreamError::Format,
                        ("{}", problem),
                        ["{}", caps_advice("sink")]
                    );
                    return false;
                }
                let changed = lock(&self.state).as_mut().is_some_and(|state| {
                    let changed = state.face_info.as_ref() != Some(&info);
                    state.face_info = Some(info.clone());
                    changed
                });
                self.side.set_fps(info.fps());
                if changed {
                    self.reset_state("caps changed");
                    self.qos.forget_cost();
                    self.obj().src_pad().mark_reconfigure();
                }
            }
            EventView::Segment(e) if is_face => {
                let segment = e.segment().clone();
                if let Some(seg) = segment.downcast_ref::<gst::ClockTime>() {
                    self.obj().update_segment(seg);
                }
                self.side.push_event(gst::event::Segment::new(&segment));
                self.reset_state("new segment");
            }
            EventView::FlushStart(_) if is_face => {
                self.side.set_flushing(true);
                self.monitor_src.push_event(gst::event::FlushStart::new());
            }
            EventView::FlushStop(_) if is_face => {
                // The task pauses itself when it sees the flush; holding its stream lock
                // waits for that iteration to end, so the pause cannot land after the
                // restart below, and no buffer from before the flush follows it.
                self.side.set_flushing(true);
                let _task = self.monitor_src.stream_lock();
                self.monitor_src
                    .push_event(gst::event::FlushStop::new(true));
                self.side.reset();
                if self.monitor_src.is_active()
                    && let Err(e) = self.side.activate(&self.monitor_src, true)
                {
                    gst::warning!(CAT, imp = self, "cannot restart monitor_src: {e}");
                }
                self.qos.reset();
                self.reset_state("flush");
            }
            EventView::FlushStop(_) => {
                lock(self.track_of(pad)).flush();
            }
            _ => {}
        }
        self.parent_sink_event(pad, event)
    }

    fn sink_query(&self, pad: &gst_base::AggregatorPad, query: &mut gst::QueryRef) -> bool {
        let is_face = pad == &self.face_pad;
        let templ = if is_face {
            video::face_caps()
        } else {
            video::monitor_caps()
        };
        match query.view_mut() {
            // The face and relit video have the same caps: ask downstream.
            gst::QueryViewMut::Caps(q) if is_face => {
                let downstream = self.obj().src_pad().peer_query_caps(Some(&templ));
                if let Some(f) = q.filter()
                    && !f.can_intersect(&templ)
                    && !self.caps_warned.swap(true, Ordering::Relaxed)
                {
                    // Upstream can only offer what this pad cannot take: negotiation
                    // will fail upstream with a bare "not-negotiated"; say why here.
                    gst::element_imp_warning!(
                        self,
                        gst::StreamError::Format,
                        ("Upstream offers only video the face pad cannot take: {}", f),
                        ["{}", caps_advice("sink")]
                    );
                }
                let caps = match q.filter() {
                    Some(f) => f.intersect_with_mode(&downstream, gst::CapsIntersectMode::First),
                    None => downstream,
                };
                q.set_result(&caps);
                true
            }
            gst::QueryViewMut::AcceptCaps(q) => {
                let caps = q.caps().to_owned();
                let ok = if !caps.can_intersect(&templ) {
                    if caps.is_fixed() {
                        gst::element_imp_error!(
                            self,
                            gst::StreamError::Format,
                            ("{} cannot take {}", pad.name(), caps),
                            ["{}", caps_advice(pad.name().as_str())]
                        );
                    }
                    false
                } else {
                    !is_face || self.obj().src_pad().peer_query_accept_caps(&caps)
                };
                q.set_result(ok);
                true
            }
            _ => self.parent_sink_query(pad, query),
        }
    }

    fn src_query(&self, query: &mut gst::QueryRef) -> bool {
        let handled = self.parent_src_query(query);
        if handled && let gst::QueryView::Latency(q) = query.view() {
            let live = q.result().0;
            gst::debug!(
                CAT,
                imp = self,
                "upstream is {}",
                if live { "live" } else { "not live" }
            );
            self.qos.set_live(live);
        }
        handled
    }

    fn src_event(&self, event: gst::Event) -> bool {
        if let gst::EventView::Qos(q) = event.view() {
            self.qos.on_event(q);
        }
        self.parent_src_event(event)
    }

    fn update_src_caps(&self, _caps: &gst::Caps) -> Result<gst::Caps, gst::FlowError> {
        self.face_pad
            .current_caps()
            .ok_or(gst_base::AGGREGATOR_FLOW_NEED_DATA)
    }

    fn next_time(&self) -> Option<gst::ClockTime> {
        let buffer = self.face_pad.peek_buffer()?;
        running_time(&self.face_pad, buffer.pts())
    }

    fn aggregate(&self, timeout: bool) -> Result<gst::FlowSuccess, gst::FlowError> {
        let Some(face) = self.face_pad.peek_buffer() else {
            if self.face_pad.is_eos() {
                // The side stream ends too, even if it never showed anything.
                gst::debug!(CAT, imp = self, "face stream ended");
                self.side.push_eos(&self.face_pad.segment());
                return Err(gst::FlowError::Eos);
            }
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        if is_gap(&face) {
            self.face_pad.drop_buffer();
            self.forward_gap(&face);
            return Ok(gst::FlowSuccess::Ok);
        }
        let started = Instant::now();
        self.sync_controlled(&face);
        let mut settings = self.settings();
        // A live stream that could not afford the denoising runs without it.
        settings.denoise &= !self.qos.denoising_dropped();
        let face_rt = running_time(&self.face_pad, face.pts());
        let Some((source, monitor_rt)) = self.source_light(face_rt, timeout, &settings) else {
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        let Some(video_target) = self.video_target(face_rt, timeout, &settings) else {
            return Err(gst_base::AGGREGATOR_FLOW_NEED_DATA);
        };
        // The peeked reference goes first: a buffer held twice is copied to be
        // written (`map_writable`), a whole frame's copy on every frame.
        drop(face);
        let buffer = self
            .face_pad
            .pop_buffer()
            .ok_or(gst_base::AGGREGATOR_FLOW_NEED_DATA)?;
        let element = self.obj();
        let late = settings.qos
            && self
                .qos
                .is_late(element.upcast_ref(), face_rt, buffer.duration());
        let mut out = self.process_frame(buffer, source, video_target, late, &settings)?;
        if late {
            let (relit, reused) = {
                let st = lock(&self.stats);
                (st.frames - st.policy.reused_late, st.policy.reused_late)
            };
            let msg = qos::late_message(
                element.upcast_ref(),
                &self.face_pad.segment(),
                &out,
                face_rt,
                relit,
                reused,
            );
            let _ = element.post_message(msg);
        }
        if let Some(rt) = monitor_rt {
            // Tells downstream which monitor frame lit this one, by its running time.
            gst::ReferenceTimestampMeta::add(
                out.make_mut(),
                &MONITOR_TIMESTAMP_CAPS,
                gst::ClockTime::from_nseconds(rt.max(0) as u64),
                gst::ClockTime::NONE,
            );
        }
        let frame_time = started.elapsed();
        if !late {
            self.qos.record_full_cost(frame_time);
            self.judge_denoising(&settings, out.duration());
        }
        let frame_seconds = frame_time.as_secs_f64();
        self.count(|st| st.stages.frame += frame_seconds);
        element.finish_buffer(out)
    }
}
