use super::*;

const PIVOT: [f64; 3] = [400.0, 250.0, -150.0];
const OFFSET: [f64; 3] = [0.0, 0.0, 120.0];
const NEST: [f64; 3] = [150.0, 0.0, 80.0];
const TOOL: [f64; 3] = [0.0, 0.0, 100.0];

fn meta() -> String {
    "# structure: XYZ-A(x)-C(z) table\n# pivot_a_mm: 400,250,-150\n# offset_c_mm: 0,0,120\n# nest_mm: 150,0,80\n# tool_mm: 0,0,100\n# source: simulated\n".to_string()
}

/// A row at angles (a, c) with the RTCP position, in header order
/// pos_x,pos_y,pos_z,a_deg,c_deg,dx_um,dy_um,dz_um.
fn row_text(a: f64, c: f64, d: [f64; 3]) -> String {
    let p = rtcp_position(PIVOT, OFFSET, NEST, TOOL, a, c);
    format!(
        "{:.6},{:.6},{:.6},{a},{c},{},{},{}",
        p[0], p[1], p[2], d[0], d[1], d[2]
    )
}

fn valid() -> String {
    let mut s = meta();
    s.push_str("pos_x,pos_y,pos_z,a_deg,c_deg,dx_um,dy_um,dz_um\n");
    s.push_str(&row_text(0.0, 0.0, [0.0; 3]));
    s.push('\n');
    s.push_str(&row_text(0.0, 90.0, [1.25, -0.5, 0.75]));
    s.push('\n');
    s.push_str(&row_text(-45.0, 0.0, [2.0, 3.0, -1.0]));
    s.push('\n');
    s
}

fn err(text: &str) -> String {
    RTestFile::parse(text, "cycle.csv").unwrap_err().to_string()
}

#[test]
fn the_nominal_positions_follow_the_format_example() {
    // rtest.md: the nominal sphere is pivot + offset + nest at A = C = 0,
    // the commanded position that minus the tool.
    let p = rtcp_position(PIVOT, OFFSET, NEST, TOOL, 0.0, 0.0);
    assert_eq!(p, [550.0, 250.0, 50.0 - 100.0]);
    // A = +90° turns the table's +z towards machine −y (right-handed about +x).
    let p = rtcp_position(PIVOT, OFFSET, NEST, TOOL, 90.0, 0.0);
    assert!(
        (p[1] - (250.0 - 200.0)).abs() < 1e-9 && (p[2] - (-150.0 - 100.0)).abs() < 1e-9,
        "{p:?}"
    );
}

#[test]
fn reads_every_field_of_a_valid_file() {
    let f = RTestFile::parse(&valid(), "cycle.csv").unwrap();
    assert_eq!(f.pivot_a_mm, PIVOT);
    assert_eq!(f.offset_c_mm, OFFSET);
    assert_eq!(f.nest_mm, NEST);
    assert_eq!(f.tool_mm, TOOL);
    assert_eq!(f.source, Source::Simulated);
    assert_eq!(f.sensors_ppm_per_k, None);
    assert_eq!(f.rows.len(), 3);
    assert_eq!(f.rows[1].c_deg, 90.0);
    assert_eq!(f.rows[1].d_um, [1.25, -0.5, 0.75]);
    assert_eq!(f.rows[2].a_deg, -45.0);
    assert!(f
        .rows
        .iter()
        .all(|r| r.time_s.is_none() && r.temps.is_empty()));
}

#[test]
fn a_spreadsheet_export_with_bom_quotes_crlf_and_other_column_order_reads_the_same() {
    let plain = RTestFile::parse(&valid(), "a.csv").unwrap();
    // columns reordered, quoted, an unknown column, CRLF, BOM, a comment and
    // a blank line among the rows, optional metadata and time/temperatures
    let mut s = String::from("\u{feff}");
    s.push_str(&meta().replace('\n', "\r\n"));
    s.push_str("# sensors_ppm_per_k: 0\r\n# operator: kim\r\n");
    s.push_str(
        "\"dz_um\",\"c_deg\",a_deg,pos_z,pos_y,pos_x,dy_um,dx_um,note,time_s,\"T_table\"\r\n",
    );
    for (i, r) in plain.rows.iter().enumerate() {
        let p = r.pos_mm;
        s.push_str(&format!(
            "\"{}\",{},{}, {:.6} ,{:.6},{:.6},{},{},x,{},\"{}\"\r\n",
            r.d_um[2],
            r.c_deg,
            r.a_deg,
            p[2],
            p[1],
            p[0],
            r.d_um[1],
            r.d_um[0],
            60 * i,
            20.5 + i as f64
        ));
        if i == 0 {
            s.push_str("\r\n# a comment between rows\r\n");
        }
    }
    let f = RTestFile::parse(&s, "b.csv").unwrap();
    assert_eq!(f.sensors_ppm_per_k, Some(0.0));
    assert_eq!(
        f.other_meta,
        vec![("operator".to_string(), "kim".to_string())]
    );
    assert_eq!(f.sensors, vec!["table".to_string()]);
    for (a, b) in f.rows.iter().zip(&plain.rows) {
        assert_eq!(
            (a.pos_mm, a.a_deg, a.c_deg, a.d_um),
            (b.pos_mm, b.a_deg, b.c_deg, b.d_um)
        );
    }
    assert_eq!(f.rows[2].time_s, Some(120.0));
    assert_eq!(f.rows[1].temps, vec![21.5]);
}

#[test]
fn written_files_read_back() {
    let mut f = RTestFile::parse(&valid(), "a.csv").unwrap();
    f.sensors = vec!["spindle".into(), "table".into()];
    for (i, r) in f.rows.iter_mut().enumerate() {
        r.time_s = Some(30.0 * i as f64);
        r.temps = vec![20.0 + i as f64, 21.125];
    }
    f.sensors_ppm_per_k = Some(11.5);
    let back = RTestFile::parse(&f.to_text(), "a.csv").unwrap();
    assert_eq!(back, f);
}

#[test]
fn missing_or_wrong_metadata_is_named() {
    let e = err(&valid().replace("# nest_mm: 150,0,80\n", ""));
    assert!(e.contains("cycle.csv") && e.contains("nest_mm"), "{e}");
    let e = err(&valid().replace("XYZ-A(x)-C(z) table", "XYZ-B(y)-C(z) table"));
    assert!(e.contains("cycle.csv:1") && e.contains("structure"), "{e}");
    let e = err(&valid().replace("# tool_mm: 0,0,100", "# tool_mm: 0,0"));
    assert!(e.contains("cycle.csv:5") && e.contains("tool_mm"), "{e}");
    let e = err(&valid().replace("source: simulated", "source: guessed"));
    assert!(e.contains("cycle.csv:6") && e.contains("source"), "{e}");
    let e = err(&valid().replace(
        "# source: simulated\n",
        "# source: simulated\n# nest_mm: 1,2,3\n",
    ));
    assert!(e.contains("twice"), "{e}");
}

#[test]
fn bad_cells_are_named_by_line_and_column() {
    let text = valid();
    let lines: Vec<&str> = text.lines().collect();
    // line 9 is the second data row (6 metadata lines, header on line 7)
    let bad = text.replace(lines[8], &lines[8].replace(",1.25,", ",1.2x5,"));
    let e = err(&bad);
    assert!(
        e.contains("cycle.csv:9") && e.contains("`dx_um`") && e.contains("1.2x5"),
        "{e}"
    );
    let e = err(&text.replace(lines[8], &lines[8].replace(",1.25,", ",,")));
    assert!(e.contains("cycle.csv:9") && e.contains("empty"), "{e}");
    let e = err(&text.replace(lines[8], &format!("{},7", lines[8])));
    assert!(e.contains("cycle.csv:9") && e.contains("9 fields"), "{e}");
    let e = err(&text.replace("dz_um\n", "dq_um\n"));
    assert!(e.contains("cycle.csv:7") && e.contains("`dz_um`"), "{e}");
    let e = err(&text.replace(lines[8], &lines[8].replace(",1.25,", ",\"1.25,")));
    assert!(e.contains("cycle.csv:9"), "{e}");
}

#[test]
fn a_position_that_does_not_put_the_sphere_at_the_nest_is_refused() {
    // the same row with the sign of A flipped: a convention mix-up
    let text = valid();
    let wrong = row_text(45.0, 0.0, [2.0, 3.0, -1.0]).replacen("45,", "-45,", 1);
    let bad = text.replace(&row_text(-45.0, 0.0, [2.0, 3.0, -1.0]), &wrong);
    let e = err(&bad);
    assert!(
        e.contains("cycle.csv:10") && e.contains("pos_y") && e.contains("put the nest"),
        "{e}"
    );
}

#[test]
fn the_first_row_must_be_the_zeroing_row() {
    let text = valid();
    let bad = text.replace(
        &row_text(0.0, 0.0, [0.0; 3]),
        &row_text(0.0, 0.0, [0.0, 0.3, 0.0]),
    );
    let e = err(&bad);
    assert!(e.contains("first row") && e.contains("0,0,0"), "{e}");
    let only_zero: String = text.lines().take(8).map(|l| format!("{l}\n")).collect();
    assert!(err(&only_zero).contains("one row"));
}

#[test]
fn time_and_temperatures_are_checked() {
    let mut f = RTestFile::parse(&valid(), "cycle.csv").unwrap();
    f.sensors = vec!["table".into()];
    for (i, r) in f.rows.iter_mut().enumerate() {
        r.time_s = Some(10.0 * i as f64);
        r.temps = vec![22.0];
    }
    f.rows[2].time_s = Some(5.0);
    let e = err(&f.to_text());
    assert!(e.contains("cycle.csv:10") && e.contains("time_s"), "{e}");
    f.rows[2].time_s = Some(50.0);
    f.rows[1].temps = vec![950.0];
    let e = err(&f.to_text());
    assert!(e.contains("cycle.csv:9") && e.contains("T_table"), "{e}");
}

#[test]
fn reads_from_disk_and_names_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nest1.csv");
    std::fs::write(&path, valid()).unwrap();
    assert_eq!(RTestFile::read(&path).unwrap().rows.len(), 3);
    std::fs::write(&path, valid().replace("# source: simulated\n", "")).unwrap();
    let e = RTestFile::read(&path).unwrap_err().to_string();
    assert!(e.contains("nest1.csv") && e.contains("source"), "{e}");
    std::fs::write(&path, [0xff, 0xfe, 0x00]).unwrap();
    let e = RTestFile::read(&path).unwrap_err().to_string();
    assert!(e.contains("nest1.csv") && e.contains("UTF-8"), "{e}");
}
