//! `tcomp geometry check`: the volumetric check's command (the check
//! itself is `tcomp_geometry::check`).

use anyhow::{bail, Result};

use std::path::PathBuf;

use tcomp_geometry::check::{
    compare, figures, plot, thermal_sim, Compared, Figures, Grid, MachineErrors,
};
use tcomp_geometry::five_axis::Turntable;
use tcomp_geometry::kinematics::Structure;
use tcomp_geometry::study::ErrorsJson;
use tcomp_numerics::rng::Rng;

#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// Errors of the machine (errors.json of `simulate`): the "measured" side.
    #[arg(long, required_unless_present = "thermal_sim")]
    pub truth: Option<PathBuf>,
    /// Errors the compensation uses (the JSON of `identify --json`).
    #[arg(long, required_unless_present = "thermal_sim")]
    pub model: Option<PathBuf>,
    /// Turntable (pivot, offsets, rotary errors) of the machine: checks the
    /// five-axis chain over A ∈ {−30, 0, 30}° × C ∈ {0, 90, 180, 270}°.
    #[arg(long)]
    pub turntable_truth: Option<PathBuf>,
    /// Turntable errors the compensation uses (default: the truth's geometry, no errors).
    #[arg(long)]
    pub turntable_model: Option<PathBuf>,
    /// Simulate the whole thermal check instead: a machine whose errors change
    /// with three temperatures, 14 lines at --states temperature states,
    /// `fit-thermal`, then --held-out unseen temperature states on the grid.
    #[arg(long)]
    pub thermal_sim: bool,
    #[arg(long, default_value_t = 8)]
    pub states: usize,
    #[arg(long, default_value_t = 4)]
    pub held_out: usize,
    /// With --thermal-sim: states with tool-tip readings (3×3×3 grid, two
    /// tools) on which the bias terms are re-optimised (seed 001 s21–s22); 0: off.
    #[arg(long, default_value_t = 3)]
    pub bias_states: usize,
    /// Noise of the tool-tip "measurement" (and of the line readings with --thermal-sim) [µm].
    #[arg(long, default_value_t = 0.5)]
    pub noise_um: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write the SVG plot (predicted vs measured; error per point before/after).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

pub fn check_cmd(a: CheckArgs) -> Result<()> {
    if !(a.noise_um >= 0.0 && a.noise_um.is_finite()) {
        bail!("--noise-um must be ≥ 0");
    }
    if a.thermal_sim {
        let c = thermal_sim(a.states, a.held_out, a.bias_states, a.noise_um, a.seed)?;
        let all = figures(&c.points.iter().collect::<Vec<_>>());
        let stat = figures(&c.static_points.iter().collect::<Vec<_>>());
        let bias =
            (!c.bias_points.is_empty()).then(|| figures(&c.bias_points.iter().collect::<Vec<_>>()));
        let per_state: Vec<serde_json::Value> = c
            .states
            .iter()
            .map(|(name, temps)| {
                let pick = |v: &[Compared]| {
                    figures(&v.iter().filter(|p| &p.state == name).collect::<Vec<_>>())
                };
                serde_json::json!({"state": name, "temps_c": temps,
                    "thermal_model": pick(&c.points), "static_geometry": pick(&c.static_points)})
            })
            .collect();
        if let Some(p) = &a.svg {
            plot(p, "held-out temperature states", &c.points)?;
        }
        if a.json {
            println!(
                "{}",
                serde_json::json!({"mode": "thermal-sim", "training_states": a.states,
                    "noise_um": a.noise_um, "seed": a.seed, "frame": "workpiece",
                    "bias_states": a.bias_states,
                    "thermal_model": all, "static_geometry": stat,
                    "thermal_model_bias_optimised": bias, "held_out_states": per_state})
            );
            return Ok(());
        }
        println!(
            "simulated thermal check: {} training states, {} held-out states × {} grid points, noise {} µm",
            a.states,
            c.states.len(),
            all.points / c.states.len().max(1),
            a.noise_um
        );
        print_figures("geometry + temperature terms", &all);
        print_figures("geometry at mean temperature (no temperature terms)", &stat);
        if let Some(b) = &bias {
            print_figures(
                &format!(
                    "temperature terms, bias optimised on tool-tip readings at {} other states",
                    a.bias_states
                ),
                b,
            );
        }
        return Ok(());
    }
    let (Some(tp), Some(mp)) = (&a.truth, &a.model) else {
        bail!("give --truth and --model (or --thermal-sim)");
    };
    let (tj, mj) = (ErrorsJson::read(tp)?, ErrorsJson::read(mp)?);
    if tj.structure != mj.structure {
        bail!(
            "structure {} of {} differs from {} of {}",
            tj.structure,
            tp.display(),
            mj.structure,
            mp.display()
        );
    }
    let st = Structure::parse(&tj.structure)?;
    let (truth, model) = (tj.to_errors()?, mj.to_errors()?);
    let tt = match &a.turntable_truth {
        Some(p) => Some(Turntable::read(p)?),
        None => None,
    };
    let tm = match (&a.turntable_model, &tt) {
        (Some(p), _) => Some(Turntable::read(p)?),
        (None, Some(t)) => Some(Turntable {
            pivot_a_mm: t.pivot_a_mm,
            offset_c_mm: t.offset_c_mm,
            ..Default::default()
        }),
        (None, None) => None,
    };
    let grid = Grid::held_out(tj.stroke_mm, tt.is_some());
    let pts = compare(
        &st,
        &MachineErrors {
            linear: &truth,
            turntable: tt.as_ref(),
        },
        &MachineErrors {
            linear: &model,
            turntable: tm.as_ref(),
        },
        tj.stroke_mm,
        &grid,
        a.noise_um,
        "check",
        &mut Rng::new(a.seed),
    );
    let f = figures(&pts.iter().collect::<Vec<_>>());
    if let Some(p) = &a.svg {
        plot(p, "held-out grid", &pts)?;
    }
    if a.json {
        println!(
            "{}",
            serde_json::json!({"mode": "files", "five_axis": tt.is_some(), "noise_um": a.noise_um,
                "frame": "workpiece", "figures": f})
        );
        return Ok(());
    }
    println!(
        "volumetric check on {} held-out points{} (noise {} µm):",
        f.points,
        if tt.is_some() {
            " with the turntable"
        } else {
            ""
        },
        a.noise_um
    );
    print_figures("compensated with the model", &f);
    Ok(())
}

fn print_figures(what: &str, f: &Figures) {
    println!(
        "  {what}: tool-tip error RMS {:.2} µm (max {:.2}) before → {:.2} µm (max {:.2}) after, {:.1} % less; residual RMS x/y/z {:.2}/{:.2}/{:.2} µm",
        f.before_rms_um,
        f.before_max_um,
        f.after_rms_um,
        f.after_max_um,
        f.reduction_pct,
        f.after_rms_xyz_um[0],
        f.after_rms_xyz_um[1],
        f.after_rms_xyz_um[2]
    );
}
