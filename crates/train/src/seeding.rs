//! Where the trainers' randomness comes from: keyed ChaCha8 streams that
//! are pure functions of `(seed, purpose, stream)`, and the lock that makes
//! seeded network initialization reproducible across concurrent trainers.
//!
//! A run's random choices at step `s` are `derived_rng(seed, purpose, s)`
//! for a purpose constant per kind of choice (batch order, times, items,
//! augmentation), so a resumed run repeats an uninterrupted one.

use std::sync::Mutex;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Serializes the seeding of libtorch's global generator with the creation
/// of a network, so concurrent trainers in one process get reproducible
/// initial weights.
pub static INIT_LOCK: Mutex<()> = Mutex::new(());

fn splitmix64(x: &mut u64) -> u64 {
    *x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator of stream `stream` of the key derived from `(seed,
/// purpose)`: a pure function of its arguments.
pub fn derived_rng(seed: u64, purpose: u64, stream: u64) -> ChaCha8Rng {
    let mut state = seed ^ purpose.wrapping_mul(0xD6E8_FEB8_6659_FD93);
    let mut key = [0u8; 32];
    for chunk in key.chunks_mut(8) {
        chunk.copy_from_slice(&splitmix64(&mut state).to_le_bytes());
    }
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(stream);
    rng
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn derived_streams_differ_by_purpose_and_stream() {
        let draw = |p, s| derived_rng(3, p, s).random::<u64>();
        assert_eq!(draw(2, 4), draw(2, 4));
        assert_ne!(draw(2, 4), draw(2, 5));
        assert_ne!(draw(2, 4), draw(1, 4));
    }
}
