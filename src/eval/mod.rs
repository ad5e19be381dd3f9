//! Measuring methods against the exact surface: geometric error from depth buffers, image
//! metrics and temporal stability ([`metrics`]), whole evaluations over scenarios, methods and
//! parameter sweeps ([`run`]), and their outputs: tables, charts and images ([`report`],
//! [`chart`], [`table`]). The definitions are written down in `docs/metrics.md`.

pub mod chart;
pub mod metrics;
pub mod oracle;
pub mod report;
pub mod run;
pub mod table;
