//! Integration tests: one target (`autotests = false`), one module per area.

mod analytic;
mod bake_props;
mod chart;
mod clean_props;
mod cli;
mod stability;
mod storage;
mod util;
