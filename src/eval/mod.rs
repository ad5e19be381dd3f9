//! Measuring methods against the exact surface: geometric error from depth buffers (see
//! [`metrics`]). The definitions are written down in `docs/metrics.md`.

pub mod metrics;
