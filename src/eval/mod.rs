//! Measuring methods against the exact surface: geometric error from depth buffers, image
//! metrics and temporal stability, defined once on the CPU ([`metrics`]) and computed where the
//! frames are on the GPU ([`gpu`], proven equal by [`check`]); FLIP ([`flip`]); whole
//! evaluations over scenarios, methods and parameter sweeps ([`run`]), and their outputs:
//! tables, charts and images ([`report`], [`chart`], [`table`]). The definitions are written
//! down in `docs/metrics.md`.

pub mod chart;
pub mod check;
pub mod flip;
pub mod gpu;
pub mod metrics;
pub mod oracle;
pub mod report;
pub mod run;
pub mod table;
