//! Tracking jobs: their options, the worker pool that runs them on the engine, and
//! the bus that carries their progress to subscribers.

pub mod bus;
pub mod options;
pub mod worker;
