//! The element, and reading what it reports: its statistics and the monitor
//! frame each relit frame used.

use gst::prelude::*;

use crate::init;

/// A new `lsydrelight` element with its default properties, but for the model:
/// the simulator's default person, whom the tests render, relit with their own
/// model (`models/default`) rather than the starter model for anyone.
pub fn element() -> gst::Element {
    init();
    gst::ElementFactory::make("lsydrelight")
        .property(
            "model-location",
            crate::default_model().to_str().expect("UTF-8 path"),
        )
        .build()
        .expect("lsydrelight element")
}

/// A counter of the element's `stats`.
pub fn stat(element: &gst::Element, field: &str) -> u64 {
    element
        .property::<gst::Structure>("stats")
        .get::<u64>(field)
        .unwrap()
}

/// Running time of the monitor frame that lit `buffer`, from its reference-timestamp meta.
pub fn monitor_time(buffer: &gst::BufferRef) -> Option<gst::ClockTime> {
    buffer
        .iter_meta::<gst::ReferenceTimestampMeta>()
        .find(|m| {
            m.reference()
                .can_intersect(&gstlsydrelight::lsydrelight::MONITOR_TIMESTAMP_CAPS)
        })
        .map(|m| m.timestamp())
}
