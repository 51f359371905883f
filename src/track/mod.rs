//! The tracker (method.md §4–§5): fit the body model to every frame's silhouette.

pub mod bench;
pub mod flips;
pub mod keyframes;
pub mod merge;
pub mod metrics;
pub mod objective;
pub mod outlines;
mod prefetch;
pub mod prior;
mod refit;
pub mod run;
pub mod shading;
pub mod simplex;
pub mod tracker;
