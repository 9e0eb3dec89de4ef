//! CSV tables: same columns, same number of rows, cell by cell (numbers within the
//! column's tolerance).

use super::Diffs;

/// Compares two CSV tables with a header row.
pub fn compare(expected: &[u8], actual: &[u8], diffs: &mut Diffs<'_>) -> Result<(), String> {
    let read = |b: &[u8], which: &str| -> Result<(Vec<String>, Vec<Vec<String>>), String> {
        let mut r = ::csv::ReaderBuilder::new().flexible(true).from_reader(b);
        let header = r
            .headers()
            .map_err(|e| format!("the {which} file is not CSV: {e}"))?
            .iter()
            .map(str::to_string)
            .collect();
        let mut rows = Vec::new();
        for rec in r.records() {
            let rec = rec.map_err(|e| format!("the {which} file is not CSV: {e}"))?;
            rows.push(rec.iter().map(str::to_string).collect());
        }
        Ok((header, rows))
    };
    let (eh, er) = read(expected, "expected")?;
    let (ah, ar) = read(actual, "actual")?;
    if eh != ah {
        diffs.push(format!(
            "columns: expected {}, actual {}",
            eh.join(","),
            ah.join(",")
        ));
        return Ok(());
    }
    if er.len() != ar.len() {
        diffs.push(format!("rows: expected {}, actual {}", er.len(), ar.len()));
    }
    for (i, (erow, arow)) in er.iter().zip(&ar).enumerate() {
        for (c, name) in eh.iter().enumerate() {
            let (ev, av) = (
                erow.get(c).map_or("", String::as_str),
                arow.get(c).map_or("", String::as_str),
            );
            if ev == av {
                continue;
            }
            // Row numbers count data rows from 1, as a spreadsheet shows them under the header.
            let path = format!("row {} {name}", i + 1);
            match (ev.trim().parse::<f64>(), av.trim().parse::<f64>()) {
                (Ok(x), Ok(y)) => diffs.number(&path, name, x, y),
                _ => diffs.text(&path, ev, av),
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::Tolerances;
    use super::*;

    #[test]
    fn cells_rows_and_columns() {
        let t = Tolerances::default();
        let mut d = Diffs::new(&t);
        compare(b"a,b\n1,x\n2,y\n", b"a,b\n1,x\n2.5,y\n3,z\n", &mut d).unwrap();
        assert_eq!(d.count, 2, "{:?}", d.listed);
        assert!(d.listed[0].contains("rows: expected 2, actual 3"));
        assert!(d.listed[1].contains("row 2 a: expected 2, actual 2.5"));
        let mut d = Diffs::new(&t);
        compare(b"a,b\n", b"a,c\n", &mut d).unwrap();
        assert_eq!(d.count, 1);
    }
}
