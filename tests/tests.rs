//! Integration tests: one target (`autotests = false`), one module per area.

mod analytic;
mod bake_props;
mod chart;
mod clean_props;
mod cli;
mod convert_mitsuba;
mod estimator;
mod export;
mod fuzz_args;
mod hostile_bake;
mod safety;
mod schedulers;
mod shards;
mod stability;
mod storage;
mod sun;
mod util;
#[cfg(feature = "viewer")]
mod view;
#[cfg(feature = "viewer")]
mod view_backdrop;
