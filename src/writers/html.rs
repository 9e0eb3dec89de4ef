//! A self-contained HTML page (inline style, images by relative path) that opens from
//! disk with no network.

use super::Output;
use std::io::Write;

/// One figure on the page.
#[derive(Clone, Debug)]
pub struct Figure {
    /// Path of the image relative to the page.
    pub src: String,
    /// Caption under the image.
    pub caption: String,
}

/// A section: heading, paragraphs, figures and an optional table.
#[derive(Clone, Debug, Default)]
pub struct Section {
    /// Heading.
    pub heading: String,
    /// Paragraphs of plain text.
    pub paragraphs: Vec<String>,
    /// Figures.
    pub figures: Vec<Figure>,
    /// Table: header cells and rows of cells.
    pub table: Option<(Vec<String>, Vec<Vec<String>>)>,
}

/// The whole page.
#[derive(Clone, Debug, Default)]
pub struct Page {
    /// Title.
    pub title: String,
    /// Sections in order.
    pub sections: Vec<Section>,
}

/// Escapes text for HTML content and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

const STYLE: &str = "body{font-family:sans-serif;margin:2em;max-width:1500px;color:#222}\
figure{display:inline-block;margin:0.5em;vertical-align:top}\
figure img{max-width:700px;width:100%;border:1px solid #ddd}\
figure.wide img{max-width:1000px}\
figcaption{font-size:0.9em;color:#555}\
table{border-collapse:collapse;font-size:0.85em}\
td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}\
th{background:#f0f0f0}";

impl Page {
    /// The page as HTML text.
    pub fn render(&self) -> String {
        let mut h = String::new();
        h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
        h.push_str(&format!("<title>{}</title>\n", escape(&self.title)));
        h.push_str(&format!("<style>{STYLE}</style>\n</head>\n<body>\n"));
        h.push_str(&format!("<h1>{}</h1>\n", escape(&self.title)));
        for s in &self.sections {
            h.push_str(&format!("<h2>{}</h2>\n", escape(&s.heading)));
            for p in &s.paragraphs {
                h.push_str(&format!("<p>{}</p>\n", escape(p)));
            }
            for f in &s.figures {
                let class = if s.figures.len() == 1 {
                    " class=\"wide\""
                } else {
                    ""
                };
                h.push_str(&format!(
                    "<figure{class}><a href=\"{src}\"><img src=\"{src}\" alt=\"{cap}\"></a>\
                     <figcaption>{cap}</figcaption></figure>\n",
                    src = escape(&f.src),
                    cap = escape(&f.caption)
                ));
            }
            if let Some((header, rows)) = &s.table {
                h.push_str("<table>\n<tr>");
                for c in header {
                    h.push_str(&format!("<th>{}</th>", escape(c)));
                }
                h.push_str("</tr>\n");
                for r in rows {
                    h.push_str("<tr>");
                    for c in r {
                        h.push_str(&format!("<td>{}</td>", escape(c)));
                    }
                    h.push_str("</tr>\n");
                }
                h.push_str("</table>\n");
            }
        }
        h.push_str("</body>\n</html>\n");
        h
    }
}

impl Output for Page {
    fn extension(&self) -> &'static str {
        "html"
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        out.write_all(self.render().as_bytes())
    }
}
