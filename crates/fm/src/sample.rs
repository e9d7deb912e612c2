//! ODE sampling.
