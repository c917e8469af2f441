//! `cargo xtask commits [RANGE]`: check the commit messages of a branch against the project's
//! rule: a subject of at most [`MAX_SUBJECT`] characters, a blank line, then a body that says
//! why. Merge commits are not checked. Before merging a branch: `cargo xtask commits
//! main..HEAD`.
use anyhow::{bail, Context, Result};
use std::process::Command;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Commits to check, as `git log` takes them.
    #[arg(default_value = "main..HEAD")]
    pub range: String,
}

/// Longest subject line [characters]: what `git log --oneline` and most tools show whole.
pub const MAX_SUBJECT: usize = 72;

/// What breaks the rule in one commit message (empty: nothing).
pub fn problems(message: &str) -> Vec<String> {
    let mut lines = message.lines();
    let subject = lines.next().unwrap_or("");
    let mut out = Vec::new();
    let n = subject.chars().count();
    if subject.trim().is_empty() {
        out.push("an empty subject".to_string());
    } else if n > MAX_SUBJECT {
        out.push(format!(
            "a subject of {n} characters (at most {MAX_SUBJECT})"
        ));
    }
    match lines.next() {
        Some(l) if !l.trim().is_empty() => out.push("no blank line after the subject".into()),
        _ => {}
    }
    if lines.all(|l| l.trim().is_empty()) {
        out.push("no body saying why".into());
    }
    out
}

pub fn run(args: Args) -> Result<()> {
    let out = Command::new("git")
        .args(["log", "--no-merges", "--format=%h%x00%B%x1e", &args.range])
        .output()
        .context("cannot run git")?;
    if !out.status.success() {
        bail!(
            "git log {}: {}",
            args.range,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let (mut checked, mut broken) = (0, 0);
    for record in text.split('\x1e') {
        let Some((hash, message)) = record.trim_start_matches('\n').split_once('\0') else {
            continue;
        };
        checked += 1;
        let p = problems(message);
        if !p.is_empty() {
            broken += 1;
            let subject = message.lines().next().unwrap_or("");
            println!("{hash} {subject}\n    {}", p.join("; "));
        }
    }
    if broken > 0 {
        bail!(
            "{broken} of {checked} commits in {} break the message rule",
            args.range
        );
    }
    println!(
        "{checked} commits in {}: every subject at most {MAX_SUBJECT} characters, every body \
         present",
        args.range
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_short_subject_a_blank_line_and_a_body_pass() {
        assert!(problems("Refuse a log without time\n\nA log without t has no rate.\n").is_empty());
    }

    #[test]
    fn a_long_subject_a_missing_blank_line_or_body_are_each_named() {
        let long = "x".repeat(MAX_SUBJECT + 1);
        assert_eq!(problems(&format!("{long}\n\nWhy.")).len(), 1);
        assert!(problems(&"x".repeat(MAX_SUBJECT)).contains(&"no body saying why".to_string()));
        // Without the blank line git reads both lines as one subject paragraph: no body.
        assert_eq!(
            problems("Fix it\nbecause"),
            vec![
                "no blank line after the subject".to_string(),
                "no body saying why".to_string()
            ]
        );
        assert_eq!(
            problems("Fix it\n\n\n"),
            vec!["no body saying why".to_string()]
        );
        assert_eq!(problems("").len(), 2);
    }
}
