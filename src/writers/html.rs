//! A self-contained HTML page (inline style, no script, images by relative path) that
//! opens from disk with no network: a table of contents, sections with a responsive grid
//! of figures, tables and lists of links to the files beside the page.

use super::Output;
use std::io::Write;

/// One figure on the page.
#[derive(Clone, Debug, Default)]
pub struct Figure {
    /// Path of the image relative to the page.
    pub src: String,
    /// Caption under the image (the figure's title).
    pub caption: String,
    /// One or two sentences on how to read it; empty for none.
    pub read: String,
    /// What to conclude from it, from the values drawn; empty for none.
    pub conclusion: String,
    /// Spans the whole width of the grid (large multi-panel figures).
    pub wide: bool,
}

impl Figure {
    /// A figure with a caption and no reading note.
    pub fn new(src: impl Into<String>, caption: impl Into<String>) -> Figure {
        Figure {
            src: src.into(),
            caption: caption.into(),
            ..Figure::default()
        }
    }
}

/// A link to a file beside the page.
#[derive(Clone, Debug, Default)]
pub struct Link {
    /// Path relative to the page.
    pub href: String,
    /// What the file holds; empty for none.
    pub note: String,
}

/// A titled list of links; long lists are folded (`<details>`) so the page stays short.
#[derive(Clone, Debug, Default)]
pub struct LinkGroup {
    /// Title of the list.
    pub title: String,
    /// The links in order.
    pub links: Vec<Link>,
    /// Folded until opened.
    pub folded: bool,
}

/// A section: heading, paragraphs, figures, notes, links and an optional table.
#[derive(Clone, Debug, Default)]
pub struct Section {
    /// Heading.
    pub heading: String,
    /// A subsection (`h3`, not in the table of contents) of the section before it.
    pub sub: bool,
    /// Paragraphs of plain text.
    pub paragraphs: Vec<String>,
    /// Figures, laid out in a grid.
    pub figures: Vec<Figure>,
    /// Short notes after the figures (e.g. plots not drawn and why).
    pub notes: Vec<String>,
    /// Lists of links.
    pub links: Vec<LinkGroup>,
    /// Table: header cells and rows of cells.
    pub table: Option<(Vec<String>, Vec<Vec<String>>)>,
    /// Tooltips of the table's header cells (same order; may be shorter or empty).
    pub column_notes: Vec<String>,
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
///
/// Hand-written rather than with `html-escape` or `v_htmlescape` (reviewed for issue
/// 33): the five characters escaped here are the ones text and quoted attribute values
/// need. `v_htmlescape::escape` and `html_escape::encode_safe` also turn `/` into
/// `&#x2f;` and `'` into `&#x27;`, so every path on the page (`plots/crossroad/...`) would
/// change its bytes for no reader's gain; `html_escape::encode_double_quoted_attribute`
/// leaves `'` alone and `encode_text` leaves `"` alone, so neither alone serves both
/// places. Measured on "rain 7 mm/h & fog <200 m> \"a\" it's plots/crossroad/x.png":
/// only this function gives the page's current bytes.
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

/// Escapes a relative path for an `href` or `src`: each segment percent-encoded where a
/// browser would misread it (`%`, `#`, `?`, spaces, quotes), then HTML-escaped.
pub fn escape_path(path: &str) -> String {
    let mut out = String::with_capacity(path.len());
    for b in path.bytes() {
        match b {
            b'%' | b'#' | b'?' | b' ' | b'"' | b'\'' | b'<' | b'>' | b'&' => {
                out.push_str(&format!("%{b:02X}"))
            }
            0..=0x1f | 0x7f..=0xff => out.push_str(&format!("%{b:02X}")),
            _ => out.push(b as char),
        }
    }
    out
}

// The grid fills the window with as many 440 px columns as fit (one on a phone); large
// figures span a whole row. Wide tables scroll sideways instead of widening the page.
const STYLE: &str = "body{font-family:sans-serif;margin:1.5em auto;max-width:1800px;\
padding:0 1.5em;color:#222;line-height:1.4}\
h2{border-bottom:1px solid #ddd;padding-bottom:0.2em;margin-top:1.6em}\
nav ul{columns:3 16em;margin:0.3em 0}\
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(min(100%,440px),1fr));\
gap:1.2em;margin:0.8em 0}\
figure{margin:0;min-width:0}\
figure.wide{grid-column:1/-1;max-width:1100px}\
figure img{width:100%;height:auto;border:1px solid #ddd}\
figcaption{font-size:0.95em;font-weight:bold;margin-top:0.2em}\
p.read{font-size:0.88em;color:#555;margin:0.2em 0 0}\
p.conclusion{font-size:0.88em;margin:0.3em 0 0}\
.scroll{overflow-x:auto;max-width:100%}\
table{border-collapse:collapse;font-size:0.85em;font-variant-numeric:tabular-nums}\
td,th{border:1px solid #ccc;padding:2px 6px;text-align:right;white-space:nowrap}\
th{background:#f0f0f0}\
th[title]{text-decoration:underline dotted;cursor:help}\
ul.files{columns:2 28em;font-size:0.92em;overflow-wrap:anywhere}\
ul.files span{color:#555}\
.note{color:#555}";

fn anchor(i: usize) -> String {
    format!("s{i}")
}

impl Page {
    /// The page as HTML text.
    pub fn render(&self) -> String {
        let mut h = String::new();
        h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
        h.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
        h.push_str(&format!("<title>{}</title>\n", escape(&self.title)));
        h.push_str(&format!("<style>{STYLE}</style>\n</head>\n<body>\n"));
        h.push_str(&format!("<h1>{}</h1>\n", escape(&self.title)));
        let top: Vec<(usize, &Section)> = self
            .sections
            .iter()
            .enumerate()
            .filter(|(_, s)| !s.sub)
            .collect();
        if top.len() > 2 {
            h.push_str("<nav><ul>\n");
            for (i, s) in top {
                h.push_str(&format!(
                    "<li><a href=\"#{}\">{}</a></li>\n",
                    anchor(i),
                    escape(&s.heading)
                ));
            }
            h.push_str("</ul></nav>\n");
        }
        for (i, s) in self.sections.iter().enumerate() {
            let tag = if s.sub { "h3" } else { "h2" };
            h.push_str(&format!(
                "<{tag} id=\"{}\">{}</{tag}>\n",
                anchor(i),
                escape(&s.heading)
            ));
            for p in &s.paragraphs {
                h.push_str(&format!("<p>{}</p>\n", escape(p)));
            }
            render_figures(&mut h, &s.figures);
            for n in &s.notes {
                h.push_str(&format!("<p class=\"note\">{}</p>\n", escape(n)));
            }
            for g in &s.links {
                render_links(&mut h, g);
            }
            if let Some((header, rows)) = &s.table {
                render_table(&mut h, header, &s.column_notes, rows);
            }
        }
        h.push_str("</body>\n</html>\n");
        h
    }
}

fn render_figures(h: &mut String, figures: &[Figure]) {
    if figures.is_empty() {
        return;
    }
    h.push_str("<div class=\"grid\">\n");
    for f in figures {
        let class = if f.wide { " class=\"wide\"" } else { "" };
        let read = if f.read.is_empty() {
            String::new()
        } else {
            format!("<p class=\"read\">{}</p>", escape(&f.read))
        };
        let conclusion = if f.conclusion.is_empty() {
            String::new()
        } else {
            format!("<p class=\"conclusion\">{}</p>", escape(&f.conclusion))
        };
        h.push_str(&format!(
            "<figure{class}><a href=\"{src}\"><img src=\"{src}\" alt=\"{cap}\"></a>\
             <figcaption>{cap}</figcaption>{read}{conclusion}</figure>\n",
            src = escape_path(&f.src),
            cap = escape(&f.caption)
        ));
    }
    h.push_str("</div>\n");
}

fn render_links(h: &mut String, g: &LinkGroup) {
    let items: String = g
        .links
        .iter()
        .map(|l| {
            let note = if l.note.is_empty() {
                String::new()
            } else {
                format!(" <span>{}</span>", escape(&l.note))
            };
            format!(
                "<li><a href=\"{}\">{}</a>{note}</li>\n",
                escape_path(&l.href),
                escape(&l.href)
            )
        })
        .collect();
    if g.folded {
        h.push_str(&format!(
            "<details><summary>{} ({} files)</summary>\n<ul class=\"files\">\n{items}</ul>\n</details>\n",
            escape(&g.title),
            g.links.len()
        ));
    } else {
        h.push_str(&format!(
            "<p>{}</p>\n<ul class=\"files\">\n{items}</ul>\n",
            escape(&g.title)
        ));
    }
}

fn render_table(h: &mut String, header: &[String], notes: &[String], rows: &[Vec<String>]) {
    h.push_str("<div class=\"scroll\"><table>\n<tr>");
    for (i, c) in header.iter().enumerate() {
        match notes.get(i).filter(|n| !n.is_empty()) {
            Some(n) => h.push_str(&format!("<th title=\"{}\">{}</th>", escape(n), escape(c))),
            None => h.push_str(&format!("<th>{}</th>", escape(c))),
        }
    }
    h.push_str("</tr>\n");
    for r in rows {
        h.push_str("<tr>");
        for c in r {
            h.push_str(&format!("<td>{}</td>", escape(c)));
        }
        h.push_str("</tr>\n");
    }
    h.push_str("</table></div>\n");
}

impl Output for Page {
    fn extension(&self) -> &'static str {
        "html"
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        out.write_all(self.render().as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_and_text_are_escaped() {
        assert_eq!(escape_path("cells/a b/x#1.json"), "cells/a%20b/x%231.json");
        assert_eq!(
            escape_path("rain.rate_mm_h=7_seed=1.json"),
            "rain.rate_mm_h=7_seed=1.json"
        );
        let page = Page {
            title: "a<b".into(),
            sections: vec![Section {
                heading: "h".into(),
                figures: vec![Figure::new("p/x y.png", "t \"q\"")],
                ..Section::default()
            }],
        };
        let html = page.render();
        assert!(html.contains("<title>a&lt;b</title>"));
        assert!(html.contains("src=\"p/x%20y.png\""));
        assert!(html.contains("alt=\"t &quot;q&quot;\""));
        assert!(!html.contains("<script"));
    }
}
