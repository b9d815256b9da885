//! The 21 geometric errors of a three-axis machine, ISO 230-1 names.
//!
//! Units: positions in mm, translational errors (`EXK`, `EYK`, `EZK`) in µm,
//! angular errors (`EAK`, `EBK`, `ECK`) and squareness in µrad. Every error
//! function is zero at its axis's zero (K = 0), so it is a polynomial without
//! a constant term.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];
    pub fn index(self) -> usize {
        self as usize
    }
    pub fn letter(self) -> char {
        ['X', 'Y', 'Z'][self.index()]
    }
    pub fn from_letter(c: char) -> Option<Axis> {
        match c.to_ascii_uppercase() {
            'X' => Some(Axis::X),
            'Y' => Some(Axis::Y),
            'Z' => Some(Axis::Z),
            _ => None,
        }
    }
}

/// Which error motion of an axis: three translations, three rotations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Component {
    /// Translation along x, y, z [µm].
    Ex,
    Ey,
    Ez,
    /// Rotation about x, y, z [µrad].
    Ea,
    Eb,
    Ec,
}

impl Component {
    pub const ALL: [Component; 6] = [
        Component::Ex,
        Component::Ey,
        Component::Ez,
        Component::Ea,
        Component::Eb,
        Component::Ec,
    ];
    pub fn index(self) -> usize {
        self as usize
    }
    pub fn is_angular(self) -> bool {
        self.index() >= 3
    }
    pub fn unit(self) -> &'static str {
        if self.is_angular() {
            "urad"
        } else {
            "um"
        }
    }
}

/// One of the 18 position-dependent errors, e.g. `EBX` = pitch of X.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Term {
    pub axis: Axis,
    pub component: Component,
}

impl Term {
    /// The 18 terms, axis by axis in ISO order EXX, EYX, EZX, EAX, EBX, ECX, EXY, …
    pub fn all() -> impl Iterator<Item = Term> {
        Axis::ALL.into_iter().flat_map(|axis| {
            Component::ALL
                .into_iter()
                .map(move |component| Term { axis, component })
        })
    }
    pub fn name(self) -> String {
        let c = ['X', 'Y', 'Z', 'A', 'B', 'C'][self.component.index()];
        format!("E{c}{}", self.axis.letter())
    }
    pub fn parse(name: &str) -> Option<Term> {
        let b: Vec<char> = name.trim().to_ascii_uppercase().chars().collect();
        if b.len() != 3 || b[0] != 'E' {
            return None;
        }
        let component = match b[1] {
            'X' => Component::Ex,
            'Y' => Component::Ey,
            'Z' => Component::Ez,
            'A' => Component::Ea,
            'B' => Component::Eb,
            'C' => Component::Ec,
            _ => return None,
        };
        Some(Term {
            axis: Axis::from_letter(b[2])?,
            component,
        })
    }
    /// Roll: the rotation about the axis's own direction (EAX, EBY, ECZ).
    pub fn is_roll(self) -> bool {
        self.component.is_angular() && self.component.index() - 3 == self.axis.index()
    }
    /// Straightness: a translation across the axis's own direction.
    pub fn is_straightness(self) -> bool {
        !self.component.is_angular() && self.component.index() != self.axis.index()
    }
}

/// The three squareness errors [µrad], signs as in
/// docs/formats/displacement-lines.md: X is the reference; Y is the nominal
/// Y rotated about +z by `EC0Y`; Z is rotated about +x by `EA0Z` and about +y
/// by `EB0Z`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Squareness {
    #[serde(rename = "EC0Y")]
    pub c0y: f64,
    #[serde(rename = "EB0Z")]
    pub b0z: f64,
    #[serde(rename = "EA0Z")]
    pub a0z: f64,
}

pub const SQUARENESS_NAMES: [&str; 3] = ["EC0Y", "EB0Z", "EA0Z"];

impl Squareness {
    pub fn get(&self, i: usize) -> f64 {
        [self.c0y, self.b0z, self.a0z][i]
    }
    pub fn set(&mut self, i: usize, v: f64) {
        match i {
            0 => self.c0y = v,
            1 => self.b0z = v,
            _ => self.a0z = v,
        }
    }
}

/// An error function of one axis position: `Σ_{j=1..n} c_j (q / scale)^j`,
/// zero at q = 0. `scale_mm` (the axis stroke) keeps the coefficients of
/// high powers in the same range as the values.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Poly {
    pub scale_mm: f64,
    /// c_1 … c_n in the term's unit (µm or µrad).
    pub coeffs: Vec<f64>,
}

impl Poly {
    pub fn zero() -> Poly {
        Poly {
            scale_mm: 1.0,
            coeffs: Vec::new(),
        }
    }
    pub fn new(scale_mm: f64, coeffs: Vec<f64>) -> Poly {
        Poly { scale_mm, coeffs }
    }
    pub fn eval(&self, q_mm: f64) -> f64 {
        let u = q_mm / self.scale_mm;
        // Horner over c_n … c_1, then one more factor u for the missing constant.
        self.coeffs.iter().rev().fold(0.0, |acc, c| acc * u + c) * u
    }
    pub fn scaled(&self, factor: f64) -> Poly {
        Poly {
            scale_mm: self.scale_mm,
            coeffs: self.coeffs.iter().map(|c| c * factor).collect(),
        }
    }
}

/// All 21 errors of a three-axis machine.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GeometricErrors {
    /// `funcs[axis][component]`.
    pub funcs: [[Poly; 6]; 3],
    pub squareness: Squareness,
}

impl GeometricErrors {
    pub fn zero() -> GeometricErrors {
        GeometricErrors::default()
    }
    pub fn get(&self, t: Term) -> &Poly {
        &self.funcs[t.axis.index()][t.component.index()]
    }
    pub fn set(&mut self, t: Term, p: Poly) {
        self.funcs[t.axis.index()][t.component.index()] = p;
    }
    /// Value of one term at its axis position [µm or µrad].
    pub fn value(&self, t: Term, q_mm: f64) -> f64 {
        let p = self.get(t);
        if p.coeffs.is_empty() {
            0.0
        } else {
            p.eval(q_mm)
        }
    }
    /// Every error multiplied by `factor` (for the second-order tests).
    pub fn scaled(&self, factor: f64) -> GeometricErrors {
        let mut out = self.clone();
        for t in Term::all() {
            out.set(t, self.get(t).scaled(factor));
        }
        for i in 0..3 {
            out.squareness.set(i, self.squareness.get(i) * factor);
        }
        out
    }
}

/// Parse a term name or fail with the list of valid names.
pub fn parse_term(name: &str) -> Result<Term> {
    match Term::parse(name) {
        Some(t) => Ok(t),
        None => bail!("unknown error term {name:?} (expected ISO 230-1 names like EXX, EBY, ECZ)"),
    }
}
