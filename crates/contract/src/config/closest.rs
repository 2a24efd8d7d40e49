//! The name a person probably meant: one typo's worth away from what they typed. One rule for
//! every list of names a command knows (topics, scenarios), so every "did you mean" agrees.

/// At most this many single-character edits away counts as a typo.
pub const MAX_TYPO: usize = 2;

/// The name of `names` closest to `given` within [`MAX_TYPO`] edits, if any (the first of
/// equally close ones).
pub fn closest<'a>(given: &str, names: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    names
        .into_iter()
        .map(|n| (strsim::levenshtein(given, n), n))
        .filter(|(d, _)| *d <= MAX_TYPO)
        .min_by_key(|(d, _)| *d)
        .map(|(_, n)| n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_typo_finds_its_name_and_a_stranger_finds_none() {
        let names = ["cut-in", "cut-out", "steady-follow"];
        assert_eq!(closest("cutin", names), Some("cut-in"));
        assert_eq!(closest("steady-folow", names), Some("steady-follow"));
        assert_eq!(closest("motorway", names), None);
    }
}
