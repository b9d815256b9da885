//! The bench's printing and its headline: counts over the cases, the
//! table of figures, the steady blocks where a re-zero did not hold.

use serde_json::{json, Value};

/// How many cases the default loses, by metric.
pub fn headline(cases: &[Value]) -> Value {
    let count = |key: &str, metric: &str| {
        cases
            .iter()
            .filter(|c| c[key][metric].as_bool() == Some(true))
            .count()
    };
    let scored = |key: &str, metric: &str| {
        cases
            .iter()
            .filter(|c| c[key][metric].as_bool().is_some())
            .count()
    };
    let mut h = serde_json::Map::new();
    h.insert("cases".into(), json!(cases.len()));
    for key in [
        "default_worse_than_ridge",
        "default_worse_than_ridge_all",
        "default_worse_than_raw_rezero",
    ] {
        h.insert(
            key.into(),
            json!({
                "mae": count(key, "mae"), "rms": count(key, "rms"),
                "of_mae": scored(key, "mae"), "of_rms": scored(key, "rms"),
            }),
        );
    }
    let total = |k: &str| {
        cases
            .iter()
            .filter_map(|c| c["rezero_promise"][k].as_u64())
            .sum::<u64>()
    };
    h.insert(
        "steady_blocks_worse_than_raw_rezero".into(),
        json!({"blocks": total("blocks"), "mae": total("worse_mae"), "rms": total("worse_rms")}),
    );
    Value::Object(h)
}

fn f2(v: &Value) -> String {
    v.as_f64().map_or("-".into(), |x| format!("{x:.2}"))
}

pub fn one_line(c: &Value) -> String {
    let m = &c["models"];
    format!(
        "{}: chosen {}, outside {}/{} %, MAE default {} ridge {} ridge-all {} mlr {} net {} raw-rezero {}; steady blocks worse than raw after a re-zero: MAE {} RMS {} of {}",
        c["case"].as_str().unwrap_or(""),
        c["chosen"].as_str().unwrap_or(""),
        f2(&c["outside_envelope_pct"]["default_inputs"]),
        f2(&c["outside_envelope_pct"]["all_inputs"]),
        f2(&m["default"]["mae_um"]),
        f2(&m["ridge"]["mae_um"]),
        f2(&m["ridge_all"]["mae_um"]),
        f2(&m["mlr"]["mae_um"]),
        f2(&m["ga_bpn"]["mae_um"]),
        f2(&m["raw_rezero"]["mae_um"]),
        c["rezero_promise"]["worse_mae"],
        c["rezero_promise"]["worse_rms"],
        c["rezero_promise"]["blocks"],
    )
}

pub fn print_table(out: &Value) {
    println!(
        "served part, MAE / RMS µm (default = fit + export replayed on the board's arithmetic)"
    );
    println!(
        "{:<28} {:<10} {:>6} {:>6}  {:>11} {:>11} {:>11} {:>11} {:>11} {:>11} {:>11}",
        "case",
        "chosen",
        "out%m",
        "out%a",
        "default",
        "ridge",
        "ridge-all",
        "mlr",
        "ga-bpn",
        "raw-rezero",
        "def-rezero"
    );
    let empty = vec![];
    for c in out["cases"].as_array().unwrap_or(&empty) {
        let m = &c["models"];
        let p = |k: &str| format!("{}/{}", f2(&m[k]["mae_um"]), f2(&m[k]["rms_um"]));
        println!(
            "{:<28} {:<10} {:>6} {:>6}  {:>11} {:>11} {:>11} {:>11} {:>11} {:>11} {:>11}",
            c["case"].as_str().unwrap_or(""),
            c["chosen"].as_str().unwrap_or(""),
            f2(&c["outside_envelope_pct"]["default_inputs"]),
            f2(&c["outside_envelope_pct"]["all_inputs"]),
            p("default"),
            p("ridge"),
            p("ridge_all"),
            p("mlr"),
            p("ga_bpn"),
            p("raw_rezero"),
            p("default_rezero"),
        );
    }
    let h = &out["headline"];
    let n = h["cases"].as_u64().unwrap_or(0);
    for (key, what) in [
        (
            "default_worse_than_ridge",
            "worse than the fit's ridge by > 5 %",
        ),
        (
            "default_worse_than_ridge_all",
            "worse than a plain ridge on every input by > 5 %",
        ),
        (
            "default_worse_than_raw_rezero",
            "worse than the raw error after a re-zero",
        ),
    ] {
        println!(
            "default {what}: MAE {} / RMS {} of {n} cases",
            h[key]["mae"], h[key]["rms"]
        );
    }
    println!(
        "(out%m: served rows with a default-model input outside its training range; out%a: any temperature rise or the spindle speed outside; {:.0} s)",
        out["seconds"].as_f64().unwrap_or(f64::NAN)
    );
    print_promise(out);
}

/// "A re-zero is a promise": per case, the steady blocks and those where
/// the board is worse than the raw error about the re-zero, with why.
fn print_promise(out: &Value) {
    let r = &out["steady_rezero_rule"];
    println!(
        "\nre-zero at the start of each steady block of the served part (spindle unchanged, median temperature rate < {} K/h over {} min, >= {} min): default vs raw about the re-zero",
        r["max_median_rate_k_per_h"],
        r["rate_window_s"].as_f64().unwrap_or(f64::NAN) / 60.0,
        r["min_block_s"].as_f64().unwrap_or(f64::NAN) / 60.0
    );
    let empty = vec![];
    for c in out["cases"].as_array().unwrap_or(&empty) {
        let p = &c["rezero_promise"];
        println!(
            "{:<28} blocks {:>2}, worse MAE {} RMS {}",
            c["case"].as_str().unwrap_or(""),
            p["blocks"],
            p["worse_mae"],
            p["worse_rms"]
        );
        for b in p["steady_blocks"].as_array().unwrap_or(&empty) {
            if b["worse_mae"] != true && b["worse_rms"] != true {
                continue;
            }
            println!(
                "    {}-{} h at {} rpm: MAE {} vs raw {} (+{}), RMS {} vs raw {} (+{}); beyond envelope {} %, inputs outside (% rows) {}",
                f2(&b["start_h"]),
                f2(&json!(b["start_h"].as_f64().unwrap_or(f64::NAN) + b["hours"].as_f64().unwrap_or(f64::NAN))),
                b["spindle_rpm"],
                f2(&b["mae_um"]),
                f2(&b["raw_mae_um"]),
                f2(&b["worse_mae_by_um"]),
                f2(&b["rms_um"]),
                f2(&b["raw_rms_um"]),
                f2(&b["worse_rms_by_um"]),
                f2(&b["beyond_envelope_pct"]),
                b["inputs_outside_pct"]
            );
        }
    }
    let h = &out["headline"]["steady_blocks_worse_than_raw_rezero"];
    println!(
        "steady blocks worse than the raw error after a re-zero: MAE {} / RMS {} of {}",
        h["mae"], h["rms"], h["blocks"]
    );
}
