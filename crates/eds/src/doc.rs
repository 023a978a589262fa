//! Markdown documentation of a device from its EDS: identity, bit rates and an object table.

use crate::model::{Eds, Entry};
use std::fmt::Write as _;

/// Escapes text for a Markdown table cell.
fn cell(s: &str) -> String {
    s.replace('\\', "\\\\").replace('|', "\\|")
}

fn type_name(dt: Option<u16>) -> String {
    match dt {
        Some(t) => cantwin_canopen::od::DataType::from_index(t)
            .map_or_else(|| format!("{t:#06X}"), |ty| ty.name().to_owned()),
        None => String::new(),
    }
}

fn code_name(code: u8) -> String {
    match code {
        0x0 => "NULL".to_owned(),
        0x2 => "DOMAIN".to_owned(),
        0x5 => "DEFTYPE".to_owned(),
        0x6 => "DEFSTRUCT".to_owned(),
        0x7 => "VAR".to_owned(),
        0x8 => "ARRAY".to_owned(),
        0x9 => "RECORD".to_owned(),
        c => format!("{c:#04X}"),
    }
}

/// One table row; an empty cell is written `| |`.
fn table_row(md: &mut String, cells: &[&str]) {
    md.push('|');
    for c in cells {
        if c.is_empty() {
            md.push_str(" |");
        } else {
            let _ = write!(md, " {c} |");
        }
    }
    md.push('\n');
}

fn row(md: &mut String, dcf: bool, index: &str, sub: &str, code: &str, e: &Entry) {
    let dt = e.data_type;
    let v =
        |x: &Option<crate::EdsValue>| x.as_ref().map(|x| cell(&x.to_text(dt))).unwrap_or_default();
    let limits = match (&e.low_limit, &e.high_limit) {
        (None, None) => String::new(),
        (lo, hi) => format!("{} .. {}", v(lo), v(hi)),
    };
    let pdo = if e.pdo_mapping == Some(true) {
        "yes"
    } else {
        ""
    };
    let name = cell(&e.parameter_name);
    let ty = type_name(dt);
    let access = e.access_type.map(|a| a.eds_name()).unwrap_or_default();
    let default = v(&e.default_value);
    let mut cells = vec![index, sub, &name, code, &ty, access, pdo, &default, &limits];
    let value = v(&e.parameter_value);
    let denotation = cell(e.denotation.as_deref().unwrap_or(""));
    if dcf {
        cells.push(&value);
        cells.push(&denotation);
    }
    table_row(md, &cells);
}

/// Renders the device's documentation as Markdown.
pub fn render_markdown(eds: &Eds) -> String {
    let d = &eds.device_info;
    let mut md = String::new();
    let title = d.product_name.as_deref().unwrap_or("CANopen device");
    let _ = writeln!(md, "# {}\n", title.trim());
    if let Some(desc) = &eds.file_info.description {
        let _ = writeln!(md, "{}\n", desc.trim());
    }
    let _ = writeln!(md, "| | |\n|---|---|");
    let mut info = |k: &str, v: Option<String>| {
        if let Some(v) = v {
            let _ = writeln!(md, "| {k} | {} |", cell(&v));
        }
    };
    info("Vendor", d.vendor_name.clone());
    info("Vendor-ID", d.vendor_number.map(|v| format!("{v:#010X}")));
    info(
        "Product code",
        d.product_number.map(|v| format!("{v:#010X}")),
    );
    info("Revision", d.revision_number.map(|v| format!("{v:#010X}")));
    info("Order code", d.order_code.clone());
    let rates = d.baud_rates();
    if !rates.is_empty() {
        let r: Vec<String> = rates.iter().map(|r| format!("{r} kbit/s")).collect();
        info("Bit rates", Some(r.join(", ")));
    }
    info("RPDOs", d.nr_of_rx_pdo.map(|v| v.to_string()));
    info("TPDOs", d.nr_of_tx_pdo.map(|v| v.to_string()));
    info("PDO granularity", d.granularity.map(|v| v.to_string()));
    info(
        "LSS",
        d.lss_supported
            .map(|v| if v { "yes" } else { "no" }.to_owned()),
    );
    info("EDS file", eds.file_info.file_name.clone());
    if let Some(c) = &eds.commissioning {
        info("Node-ID", c.node_id.map(|v| v.to_string()));
        info("Node name", c.node_name.clone());
        info("Bit rate", c.baudrate.map(|v| format!("{v} kbit/s")));
        info("Network", c.network_name.clone());
    }
    if let Some(lines) = &eds.comments {
        let _ = writeln!(md, "\n{}", lines.join("\n"));
    }
    let _ = writeln!(md, "\n## Object dictionary\n");
    let dcf = eds.is_dcf();
    let mut head = vec![
        "Index", "Sub", "Name", "Object", "Type", "Access", "PDO", "Default", "Limits",
    ];
    if dcf {
        head.extend(["Value", "Denotation"]);
    }
    table_row(&mut md, &head);
    let rule = vec!["---"; head.len()];
    md.push('|');
    md.push_str(&rule.join("|"));
    md.push_str("|\n");
    for (&index, o) in &eds.objects {
        let idx = format!("{index:#06X}");
        let code = code_name(o.object_code());
        if o.subs.is_empty() {
            row(&mut md, dcf, &idx, "", &code, &o.entry);
        } else {
            let name = format!("**{}**", cell(&o.entry.parameter_name));
            let mut cells = vec![idx.as_str(), "", &name, &code, "", "", "", "", ""];
            if dcf {
                cells.extend(["", ""]);
            }
            table_row(&mut md, &cells);
            for (sub, e) in &o.subs {
                row(&mut md, dcf, "", &sub.to_string(), "", e);
            }
        }
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn escapes_pipes() {
        assert_eq!(cell("a|b"), "a\\|b");
    }
}
