//! Geodesic distances by the heat method.
