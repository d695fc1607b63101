//! "Did you mean" suggestions for misspelt kinds, parameters, ports and node ids.

/// The candidate closest to `word` by edit distance, if it is close enough to be a plausible typo
/// (at most a third of the word's length, and at least 1 edit allowed).
pub fn nearest<'a, I>(word: &str, candidates: I) -> Option<String>
where
    I: IntoIterator<Item = &'a str>,
{
    let limit = (word.chars().count() / 3).max(2);
    candidates
        .into_iter()
        .map(|c| (strsim::damerau_levenshtein(word, c), c))
        .filter(|(d, _)| *d <= limit)
        .min_by(|a, b| a.0.cmp(&b.0).then_with(|| a.1.cmp(b.1)))
        .map(|(_, c)| c.to_string())
}

/// `" (did you mean `x`?)"` for the nearest candidate, or nothing: the tail of an error message.
pub fn did_you_mean<'a, I>(word: &str, candidates: I) -> String
where
    I: IntoIterator<Item = &'a str>,
{
    nearest(word, candidates)
        .map(|s| format!(" (did you mean `{s}`?)"))
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggests_close_and_rejects_far() {
        let kinds = ["heightfield.procedural", "heightfield.read", "image.write"];
        assert_eq!(
            nearest("heightfield.procedual", kinds).as_deref(),
            Some("heightfield.procedural")
        );
        assert_eq!(
            nearest("image.wirte", kinds).as_deref(),
            Some("image.write")
        );
        assert_eq!(nearest("sss.profile", kinds), None);
    }
}
