//! An error in words, as every front end prints it.

use std::error::Error;

/// The error and its causes, joined by ": ", each cause left out where the
/// text so far already holds it (errors that show their cause in their own
/// message would otherwise print it twice).
pub fn error_text(e: &dyn Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        let more = cause.to_string();
        if !text.contains(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        source = cause.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("{0}")]
    struct Outer(String, #[source] std::io::Error);

    #[test]
    fn causes_are_joined_unless_the_text_already_holds_them() {
        let io = || std::io::Error::other("disk full");
        let e = Outer("writing out.exr".into(), io());
        assert_eq!(error_text(&e), "writing out.exr: disk full");
        let e = Outer("writing out.exr: disk full".into(), io());
        assert_eq!(error_text(&e), "writing out.exr: disk full");
    }
}
