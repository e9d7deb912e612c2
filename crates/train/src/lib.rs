#![doc = include_str!("../README.md")]

pub mod adam;
pub mod checkpoint;
pub mod error;
pub mod resume;
pub mod schedule;
pub mod seeding;
pub mod training_loop;

pub use adam::Adam;
pub use error::{Result, TrainError};
pub use schedule::LrSchedule;
pub use training_loop::{
    LOG_HEADER, LoopConfig, Objective, RunNames, StepError, TrainSummary, TrainingLoop, divergence,
    truncate_log,
};
