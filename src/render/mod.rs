//! What a person reads: plots ([`plot`]), the design's text, plots and CSV ([`mod@design`]),
//! the HTML reports ([`html`]), the calibration commands' text, JSON and plots
//! ([`calibration`]) and the sweep's table and plot ([`sweep`]). Everything here returns text
//! or bytes; writing them is [`crate::export`]'s job.

pub mod calibration;
pub mod design;
pub mod html;
pub mod plot;
pub mod sweep;
