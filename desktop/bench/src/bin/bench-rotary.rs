//! `bench-rotary [--json] [--seeds N] [--first-seed S] [--noise-um S]
//! [--thermal-cycles K] [--bias-states B] [--linear joint|fixed|known]
//! [--orders simulator|auto]`:
//! the five-axis chain of issue 31 on N random machines (default 10, seeds
//! S…S+N−1, default 1001; σ = 0.5 µm on every reading): linear errors
//! identified from 14 simulated lines, R-test files of the default plan (3
//! nests, 129 poses each) written and read back, the eight location errors
//! identified together with the component errors and a constant per file,
//! then the tool-tip error over the held-out grid (27 positions × A
//! −90…90° × C 0…315° × 2 tools) before and after, scored against the true
//! error and against the "measured" one (σ per direction). `--linear`:
//! `joint` (default) fits the 14 lines and the R-test files in one problem,
//! `fixed` takes the 14-line model as known input, `known` the true linear
//! errors (isolates the rotary fit). `--thermal-cycles K` (e.g. 18): the
//! location errors drift with three sensors over a warm-up and the grid is
//! scored at four held-out states of the cool-down; `--bias-states B`
//! (with drift): the location constants re-optimised on tool-tip readings
//! at B other cool-down states, scored beside the model without it.
//! `--orders auto`: the harmonic orders chosen by the evidence
//! (`rotary::orders`, identify-rotary's default) instead of the simulator's
//! own C 3, A 2; `orders_c_a` lists them per machine.
use tcomp_geometry::rotary::check::{run_case, CaseFigures, CaseOptions, LinearInput};

/// The command line (clap: `--help` lists every flag).
#[derive(clap::Parser)]
#[command(
    name = "bench-rotary",
    about = "The five-axis chain of issue 31 on random machines: location and component errors identified from R-test files, the tool-tip error over a held-out grid before and after"
)]
struct Args {
    /// Print the figures as one JSON object (summary and cases).
    #[arg(long)]
    json: bool,
    /// Random machines (seeds S…S+N−1).
    #[arg(long, value_name = "N", default_value_t = 10)]
    seeds: u64,
    /// The first machine's seed S (7001 for the unseen set).
    #[arg(long = "first-seed", value_name = "S", default_value_t = 1001)]
    first_seed: u64,
    /// σ of every reading, µm.
    #[arg(
        long = "noise-um",
        value_name = "UM",
        default_value_t = 0.5,
        value_parser = non_negative,
        allow_hyphen_values = true
    )]
    noise_um: f64,
    /// Drift of the location errors with three sensors over K warm-up cycles, scored at four held-out cool-down states (0: static).
    #[arg(long = "thermal-cycles", value_name = "K", default_value_t = 0)]
    thermal_cycles: usize,
    /// With drift: the location constants re-optimised on tool-tip readings at B other cool-down states.
    #[arg(long = "bias-states", value_name = "B", default_value_t = 0)]
    bias_states: usize,
    /// The linear errors: fitted with the R-test files in one problem, the 14-line model as known input, or the true ones.
    #[arg(long, value_enum, default_value_t = Linear::Joint)]
    linear: Linear,
    /// The harmonic orders: the simulator's own (C 3, A 2) or chosen by the evidence as `identify-rotary`'s default `auto` does.
    #[arg(long, value_enum, default_value_t = Orders::Simulator)]
    orders: Orders,
}

/// `--orders`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Orders {
    Simulator,
    Auto,
}

/// `--linear`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum Linear {
    Joint,
    Fixed,
    Known,
}

/// A number ≥ 0 (finite).
fn non_negative(s: &str) -> Result<f64, String> {
    s.parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v >= 0.0)
        .ok_or_else(|| "a number ≥ 0".to_string())
}

fn main() -> std::process::ExitCode {
    tcomp_data::cli_error::run_main(|| {
        let args: Args = tcomp_bench::cli::parse()?;
        let (seeds, first, json) = (args.seeds, args.first_seed, args.json);
        let o = CaseOptions {
            noise_um: args.noise_um,
            thermal_cycles: args.thermal_cycles,
            linear: match args.linear {
                Linear::Joint => LinearInput::Joint,
                Linear::Fixed => LinearInput::Fixed,
                Linear::Known => LinearInput::Known,
            },
            bias_states: args.bias_states,
            auto_orders: args.orders == Orders::Auto,
        };
        let mut cases = Vec::new();
        for seed in first..first + seeds {
            let c = run_case(seed, &o)?;
            if !json {
                print_case(&c);
            }
            cases.push(c);
        }
        let worst = |f: fn(&CaseFigures) -> f64| cases.iter().map(f).fold(0.0, f64::max);
        let least = |f: fn(&CaseFigures) -> f64| cases.iter().map(f).fold(f64::INFINITY, f64::min);
        let mean = |f: fn(&CaseFigures) -> f64| {
            cases.iter().map(f).sum::<f64>() / cases.len().max(1) as f64
        };
        let bias = |f: fn(&CaseFigures) -> Option<f64>| {
            let v: Vec<f64> = cases.iter().filter_map(f).collect();
            (!v.is_empty()).then(|| v.iter().copied().fold(f64::INFINITY, f64::min))
        };
        let summary = serde_json::json!({
            "machines": cases.len(), "first_seed": first, "noise_um": o.noise_um,
            "thermal_cycles": o.thermal_cycles, "linear_input": o.linear, "bias_states": o.bias_states,
            "location_worst_um": worst(|c| c.worst_um), "location_worst_urad": worst(|c| c.worst_urad),
            "component_rms_um_worst": worst(|c| c.component_rms_um.0), "component_true_rms_um_mean": mean(|c| c.component_rms_um.1),
            "component_rms_urad_worst": worst(|c| c.component_rms_urad.0), "component_true_rms_urad_mean": mean(|c| c.component_rms_urad.1),
            "grid_true_reduction_pct_least": least(|c| c.grid_true.reduction_pct),
            "grid_true_after_rms_um_worst": worst(|c| c.grid_true.after_rms_um),
            "grid_measured_reduction_pct_least": least(|c| c.grid.reduction_pct),
            "grid_measured_after_rms_um_worst": worst(|c| c.grid.after_rms_um),
            "grid_linear_only_reduction_pct_least": least(|c| c.grid_linear_only.reduction_pct),
            "grid_bias_true_reduction_pct_least": bias(|c| c.grid_bias_true.as_ref().map(|f| f.reduction_pct)),
            "location_worst_bias_um": bias(|c| c.worst_bias.map(|w| -w.0)).map(|v| -v),
            "location_worst_bias_urad": bias(|c| c.worst_bias.map(|w| -w.1)).map(|v| -v),
            "grid_bias_measured_reduction_pct_least": bias(|c| c.grid_bias.as_ref().map(|f| f.reduction_pct)),
            "unobservable": cases.iter().flat_map(|c| c.unobservable.clone()).collect::<Vec<_>>(),
            "orders_auto": o.auto_orders,
            "orders_c_a": cases.iter().map(|c| c.orders).collect::<Vec<_>>(),
        });
        if json {
            println!(
                "{}",
                serde_json::json!({"summary": summary, "cases": cases})
            );
        } else {
            println!("{summary:#}");
        }
        Ok(())
    })
}

fn print_case(c: &CaseFigures) {
    let bias = match (&c.grid_bias_true, &c.grid_bias) {
        (Some(t), Some(m)) => format!(
            "; bias step {:.2} µm ({:.1} %) true, {:.1} % measured",
            t.after_rms_um, t.reduction_pct, m.reduction_pct
        ),
        _ => String::new(),
    };
    println!(
        "machine {:4}: location worst {:.2} µm / {:.2} µrad; components rms {:.2} of {:.2} µm, {:.2} of {:.2} µrad; cond {:.0}; grid {:.2} → {:.2} µm true ({:.1} %), {:.2} µm measured ({:.1} %); linear model only {:.1} %{bias}",
        c.seed, c.worst_um, c.worst_urad, c.component_rms_um.0, c.component_rms_um.1,
        c.component_rms_urad.0, c.component_rms_urad.1, c.condition_number.unwrap_or(f64::INFINITY),
        c.grid_true.before_rms_um, c.grid_true.after_rms_um, c.grid_true.reduction_pct,
        c.grid.after_rms_um, c.grid.reduction_pct, c.grid_linear_only.reduction_pct
    );
}
