//! A self-contained HTML page: headings, paragraphs, tables and inline SVG charts, no
//! external scripts, styles or fonts (the file opens offline and can be mailed).
use anyhow::Result;
use std::fmt::Write;
use std::path::{Path, PathBuf};

/// Escape text for HTML.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A page being built.
#[derive(Debug, Clone, Default)]
pub struct Page {
    title: String,
    body: String,
}

impl Page {
    /// An empty page with a title.
    pub fn new(title: &str) -> Page {
        let mut p = Page {
            title: title.to_string(),
            body: String::new(),
        };
        let _ = writeln!(p.body, "<h1>{}</h1>", esc(title));
        p
    }

    /// A section heading.
    pub fn heading(&mut self, text: &str) -> &mut Self {
        let _ = writeln!(self.body, "<h2>{}</h2>", esc(text));
        self
    }

    /// A paragraph of text.
    pub fn paragraph(&mut self, text: &str) -> &mut Self {
        let _ = writeln!(self.body, "<p>{}</p>", esc(text));
        self
    }

    /// A bulleted list.
    pub fn list(&mut self, items: &[String]) -> &mut Self {
        self.body.push_str("<ul>\n");
        for it in items {
            let _ = writeln!(self.body, "<li>{}</li>", esc(it));
        }
        self.body.push_str("</ul>\n");
        self
    }

    /// An inline SVG chart (from [`super::svg`]); a chart that failed to draw becomes a note.
    pub fn chart(&mut self, svg: Result<String>) -> &mut Self {
        match svg {
            Ok(s) => {
                let _ = writeln!(self.body, "<figure>{s}</figure>");
            }
            Err(e) => {
                let _ = writeln!(
                    self.body,
                    "<p class=\"note\">(chart not drawn: {})</p>",
                    esc(&format!("{e:#}"))
                );
            }
        }
        self
    }

    /// A table with a header row.
    pub fn table(&mut self, header: &[&str], rows: &[Vec<String>]) -> &mut Self {
        self.body.push_str("<table>\n<tr>");
        for h in header {
            let _ = write!(self.body, "<th>{}</th>", esc(h));
        }
        self.body.push_str("</tr>\n");
        for r in rows {
            self.body.push_str("<tr>");
            for c in r {
                let _ = write!(self.body, "<td>{}</td>", esc(c));
            }
            self.body.push_str("</tr>\n");
        }
        self.body.push_str("</table>\n");
        self
    }

    /// The whole document.
    pub fn render(&self) -> String {
        format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <title>{}</title>\n<style>\n{}\n</style>\n</head>\n<body>\n{}</body>\n</html>\n",
            esc(&self.title),
            STYLE,
            self.body
        )
    }

    /// Write the page as `DIR/index.html` (atomically; DIR is created under the output policy
    /// of [`crate::atomic`]). Returns its path.
    pub fn write(&self, dir: &Path) -> Result<PathBuf> {
        let path = dir.join("index.html");
        crate::atomic::write_str(&path, &self.render())?;
        Ok(path)
    }
}

const STYLE: &str = "body{font-family:sans-serif;max-width:960px;margin:2em auto;color:#222}\
h1{font-size:1.6em}h2{font-size:1.25em;margin-top:1.6em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:0.6em 0}td,th{border:1px solid #bbb;padding:3px 8px;\
text-align:left}th{background:#f0f0f0}figure{margin:0.6em 0}.note{color:#666}";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn page_escapes_and_contains_its_parts() {
        let mut p = Page::new("A <b> test");
        p.paragraph("x < y & z")
            .table(&["a", "b"], &[vec!["1".into(), "2".into()]])
            .chart(Ok("<svg></svg>".into()));
        let h = p.render();
        assert!(h.contains("A &lt;b&gt; test") && h.contains("x &lt; y &amp; z"));
        assert!(h.contains("<table>") && h.contains("<td>2</td>") && h.contains("<svg></svg>"));
        let dir = tempfile::tempdir().unwrap();
        let path = p.write(&dir.path().join("r")).unwrap();
        assert!(std::fs::read_to_string(path)
            .unwrap()
            .starts_with("<!DOCTYPE html>"));
    }
}
