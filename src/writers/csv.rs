//! CSV tables: a header row and string cells, quoted as RFC 4180 wants.

use super::Output;
use std::io::Write;

/// A table to write as CSV.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CsvTable {
    /// Column names.
    pub header: Vec<String>,
    /// Rows of cells, each as long as the header.
    pub rows: Vec<Vec<String>>,
}

impl CsvTable {
    /// An empty table with these columns.
    pub fn new(header: &[&str]) -> Self {
        CsvTable {
            header: header.iter().map(|s| s.to_string()).collect(),
            rows: Vec::new(),
        }
    }
}

impl Output for CsvTable {
    fn extension(&self) -> &'static str {
        "csv"
    }

    fn write_to(&self, out: &mut dyn Write) -> std::io::Result<()> {
        let mut w = csv::Writer::from_writer(out);
        w.write_record(&self.header)?;
        for row in &self.rows {
            w.write_record(row)?;
        }
        w.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_with_commas_and_quotes_are_quoted() {
        let mut t = CsvTable::new(&["a", "b"]);
        t.rows.push(vec!["1,2".into(), "say \"hi\"".into()]);
        let mut out = Vec::new();
        t.write_to(&mut out).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "a,b\n\"1,2\",\"say \"\"hi\"\"\"\n"
        );
    }
}
