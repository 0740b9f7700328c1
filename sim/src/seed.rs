//! Seed splitting: the one function that turns (master seed, item) into an independent random
//! stream, so any episode or work item replays alone. It lives in `sim`, the lowest crate that
//! draws per-episode streams (the simulated cell's error sources); the orchestrator's
//! simulation harness and the tests use the same function. `perception` and `robots` draw no
//! per-episode streams.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// SplitMix64's step: a bijective, well-mixed function of a 64-bit value.
fn splitmix64(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The seed of item `index` (an episode, a work item) of a run seeded with `seed`:
/// SplitMix64 of the seed mixed with SplitMix64 of the index, so neighbouring seeds and
/// indices give unrelated streams.
pub fn split_seed(seed: u64, index: u64) -> u64 {
    splitmix64(seed ^ splitmix64(index))
}

/// Random stream `stream` of item `index` under `seed`: ChaCha8 keyed by [`split_seed`], on its
/// own ChaCha stream, so the streams of one item are independent and a change in how much one
/// of them draws never shifts the others.
pub fn stream_rng(seed: u64, index: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(split_seed(seed, index));
    rng.set_stream(stream);
    rng
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let draw = |seed, index, stream| stream_rng(seed, index, stream).next_u64();
        assert_eq!(draw(7, 3, 1), draw(7, 3, 1));
        let mut seen = std::collections::BTreeSet::new();
        for seed in 0..4 {
            for index in 0..16 {
                for stream in 0..6 {
                    assert!(
                        seen.insert(draw(seed, index, stream)),
                        "{seed} {index} {stream}"
                    );
                }
            }
        }
        // Neighbouring items differ in about half their bits.
        let flips = (split_seed(7, 3) ^ split_seed(7, 4)).count_ones();
        assert!((16..=48).contains(&flips), "{flips}");
    }
}
