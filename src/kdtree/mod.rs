//! The kd-tree: node layout, builder, CPU traversals.
pub mod links;
pub mod node;
pub use node::KdNode;
pub mod build;
pub mod cache;
pub mod stats;
pub mod traverse;
pub use build::{BuildConfig, BuildProgress, BuildStage, Builder, KdTree};
pub use stats::BuildStats;
