//! Integration tests: one target (`autotests = false`), one module per area.

mod analytic;
mod bake_props;
mod clean_props;
mod cli;
mod storage;
mod util;
