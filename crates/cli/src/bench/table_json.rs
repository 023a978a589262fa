//! A benchmark's Markdown table as one JSON object, for `--json`.
//!
//! The table is what `BENCHMARKS.md` records, so the JSON is read from it rather than built
//! beside it: the two cannot drift apart. Figures measured over several trials read
//! `best (median M)` or `best (median M; note)`; the median goes to its own object so that a
//! figure's value stays the best trial's, which the floors are judged on.

use serde_json::{Map, Value};

/// `{"bench": name, "figures": {...}, "medians": {...}}` from `table`.
///
/// A two-column table gives `figure: value`; a wider one gives
/// `row: {column header: value}`. `medians` has the same shape, holding only the cells that
/// name a median, and is left out when none does. Emphasis is stripped; lines outside a table
/// are skipped.
pub fn table_json(name: &str, table: &str) -> Value {
    let mut figures = Map::new();
    let mut medians = Map::new();
    let lines: Vec<&str> = table.lines().map(str::trim).collect();
    let mut header: Vec<String> = Vec::new();
    for (k, line) in lines.iter().enumerate() {
        if !line.starts_with('|') || is_rule(line) {
            continue;
        }
        let row = cells(line);
        if lines.get(k + 1).is_some_and(|next| is_rule(next)) {
            header = row;
            continue;
        }
        match row.as_slice() {
            [figure, value] => {
                let (value, median) = split_median(value);
                figures.insert(figure.clone(), Value::String(value));
                if let Some(m) = median {
                    medians.insert(figure.clone(), Value::String(m));
                }
            }
            [figure, values @ ..] if !values.is_empty() => {
                let mut row_figures = Map::new();
                let mut row_medians = Map::new();
                for (j, value) in values.iter().enumerate() {
                    let column = header
                        .get(j + 1)
                        .cloned()
                        .unwrap_or_else(|| format!("column {}", j + 2));
                    let (value, median) = split_median(value);
                    row_figures.insert(column.clone(), Value::String(value));
                    if let Some(m) = median {
                        row_medians.insert(column, Value::String(m));
                    }
                }
                figures.insert(figure.clone(), Value::Object(row_figures));
                if !row_medians.is_empty() {
                    medians.insert(figure.clone(), Value::Object(row_medians));
                }
            }
            _ => {}
        }
    }
    let mut object = Map::new();
    object.insert("bench".into(), Value::String(name.to_string()));
    object.insert("figures".into(), Value::Object(figures));
    if !medians.is_empty() {
        object.insert("medians".into(), Value::Object(medians));
    }
    Value::Object(object)
}

/// A table's separator line between header and rows: `|---|:--:|`.
fn is_rule(line: &str) -> bool {
    line.starts_with('|')
        && line.contains('-')
        && line.chars().all(|c| matches!(c, '|' | '-' | ':' | ' '))
}

/// The cells of a table row, emphasis stripped.
fn cells(line: &str) -> Vec<String> {
    line.trim_matches('|')
        .split('|')
        .map(|c| c.replace("**", "").trim().to_string())
        .collect()
}

/// `best (median M)` into `best` and `M`; `best (median M; note)` into `best (note)` and `M`;
/// a cell without a median as it is.
fn split_median(cell: &str) -> (String, Option<String>) {
    const OPEN: &str = "(median ";
    let Some(start) = cell.find(OPEN) else {
        return (cell.to_string(), None);
    };
    let after = &cell[start + OPEN.len()..];
    let Some(end) = after.find([';', ')']) else {
        return (cell.to_string(), None);
    };
    let median = after[..end].trim().to_string();
    let before = cell[..start].trim_end();
    let value = match after[end..].strip_prefix(';') {
        // The note keeps the parenthesis that closed the median's.
        Some(note) => format!("{before} ({}", note.trim_start()),
        None => format!("{before}{}", &after[end + 1..]),
    };
    (value.trim().to_string(), Some(median))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_two_column_table_gives_figures_and_their_medians() {
        let table = "| figure | best of 3 trials (median) |\n|---|---|\n\
            | bus time simulated | 60.0 s |\n\
            | **real-time factor** (bus time / wall time) | **412** (median 380) |\n\
            | **per wall second** | **3098254** (median 2876543; meets the floor of 2 000 000) |";
        let v = table_json("bus", table);
        assert_eq!(v["bench"], "bus");
        assert_eq!(v["figures"]["bus time simulated"], "60.0 s");
        assert_eq!(
            v["figures"]["real-time factor (bus time / wall time)"],
            "412"
        );
        assert_eq!(
            v["medians"]["real-time factor (bus time / wall time)"],
            "380"
        );
        assert_eq!(
            v["figures"]["per wall second"],
            "3098254 (meets the floor of 2 000 000)"
        );
        assert_eq!(v["medians"]["per wall second"], "2876543");
        assert!(v["medians"].get("bus time simulated").is_none());
    }

    #[test]
    fn a_wider_table_gives_each_row_by_column() {
        let table = "| figure | value |\n|---|---|\n| delivered frames | 42 |\n\n\
            | how (best of 2 trials; median) | wall time | real-time factor |\n|---|---|---|\n\
            | firmware | 0.667 s (median 0.700 s) | **90** (median 85; BELOW THE FLOOR of 200) |\n\
            \nThe devices' own filter: 5.3× faster.";
        let v = table_json("network", table);
        assert_eq!(v["figures"]["delivered frames"], "42");
        assert_eq!(v["figures"]["firmware"]["wall time"], "0.667 s");
        assert_eq!(v["medians"]["firmware"]["wall time"], "0.700 s");
        assert_eq!(
            v["figures"]["firmware"]["real-time factor"],
            "90 (BELOW THE FLOOR of 200)"
        );
        assert_eq!(v["medians"]["firmware"]["real-time factor"], "85");
        assert_eq!(v["figures"].as_object().unwrap().len(), 2);
    }

    #[test]
    fn a_table_without_medians_has_no_medians_object() {
        let v = table_json(
            "memory",
            "| figure | value |\n|---|---|\n| heap | 1681 bytes |",
        );
        assert_eq!(v["figures"]["heap"], "1681 bytes");
        assert!(v.get("medians").is_none());
    }

    #[test]
    fn a_cell_with_an_unclosed_median_stays_as_it_is() {
        assert_eq!(split_median("12 (median 3"), ("12 (median 3".into(), None));
        assert_eq!(
            split_median("7 (no median)"),
            ("7 (no median)".into(), None)
        );
    }
}
