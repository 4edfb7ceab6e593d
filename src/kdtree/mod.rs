//! The kd-tree: the tree ([`tree`]), its node layout, builder and parameters,
//! statistics, cache and CPU traversals.
pub mod build;
pub mod cache;
pub mod config;
pub mod links;
pub mod node;
pub mod stats;
pub mod traverse;
pub mod tree;
pub use build::{BuildProgress, BuildStage};
pub use config::{BuildConfig, Builder};
pub use node::KdNode;
pub use stats::BuildStats;
pub use tree::KdTree;
