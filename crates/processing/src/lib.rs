#![doc = include_str!("../README.md")]

pub mod decimate;
pub mod flips;
pub mod holes;
pub mod refine;
