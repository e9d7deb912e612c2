//! The GMM signal generator.
