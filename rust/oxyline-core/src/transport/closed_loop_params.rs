//! The closed loop's parameter set in the units it is published in (docs/oxygen.md "Oxygen
//! around a closed loop": L, L/min, mL/min, mmHg, g/L) converted to the SI pieces of the O2
//! loop: its compartments in flow order, its branches, the blood's Hill binding, the organ
//! beds' resistances and the prescribed flow table (half-sine ejections of both ventricles,
//! steady organ flows). The parameter set carries more (the heart, the tree); only what is read
//! here is checked here.

use crate::error::{Error, Result};
use crate::model::units::MMHG;
use serde::de::{Deserializer, MapAccess, Visitor};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use std::fmt;

/// mol per mL O2 (STPD; docs/physics.md: 1 mL = 1/22.414 mmol).
pub const ML_O2: f64 = 1.0 / 22414.0;
/// The organs' mean arterial pressure (mmHg): the beds share the cardiac output at it.
const MEAN_ARTERIAL_MMHG: f64 = 93.0;

#[derive(Debug, Clone, Deserialize)]
pub struct Blood {
    /// mL O2 dL⁻¹ mmHg⁻¹
    pub solubility: f64,
    /// g/L
    pub hemoglobin: f64,
    /// mL O2 per g Hb
    pub hufner: f64,
    /// mmHg
    pub p50: f64,
    pub hill_n: f64,
}

#[derive(Debug, Clone, Deserialize)]
pub struct Lungs {
    /// mmHg
    pub alveolar_po2: f64,
    /// mL O2 min⁻¹ mmHg⁻¹
    pub diffusing_capacity: f64,
    pub shunt_fraction: f64,
}

/// Volumes (L) of the mixing pools.
#[derive(Debug, Clone, Deserialize)]
pub struct Pools {
    pub left_heart: f64,
    pub arteries: f64,
    pub veins: f64,
    pub right_heart: f64,
    pub pulmonary_arteries: f64,
    pub pulmonary_veins: f64,
}

#[derive(Debug, Clone, Deserialize)]
pub struct Organ {
    /// Share of the cardiac output.
    pub flow_fraction: f64,
    /// Resting VO2 (mL/min).
    pub vo2: f64,
    /// Exchange volume (L).
    pub volume: f64,
}

/// The parameter set (unknown keys are the heart's and the tree's, read elsewhere).
#[derive(Debug, Clone, Deserialize)]
pub struct LoopParams {
    /// s
    pub period: f64,
    /// s
    pub dt: f64,
    /// L/min
    pub cardiac_output: f64,
    /// s, both ventricles (the prescribed table only)
    #[serde(default)]
    pub ejection_time: Option<f64>,
    pub blood: Blood,
    pub lungs: Lungs,
    pub pools: Pools,
    /// Michaelis–Menten km (mmHg) of every organ.
    pub km: f64,
    /// In the parameter set's order (it is the compartments' and branches' order).
    #[serde(deserialize_with = "in_order")]
    pub organs: Vec<(String, Organ)>,
    /// "pool" (default) or "tree": a segment-resolved arterial tree replaces the pool.
    #[serde(default = "pool")]
    pub arteries: String,
}

fn pool() -> String {
    "pool".into()
}

/// A JSON object read as (key, value) pairs in the file's order.
fn in_order<'de, D: Deserializer<'de>>(
    d: D,
) -> std::result::Result<Vec<(String, Organ)>, D::Error> {
    struct Ordered;
    impl<'de> Visitor<'de> for Ordered {
        type Value = Vec<(String, Organ)>;
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            f.write_str("a map of organ beds")
        }
        fn visit_map<A: MapAccess<'de>>(
            self,
            mut m: A,
        ) -> std::result::Result<Self::Value, A::Error> {
            let mut out = Vec::new();
            while let Some(entry) = m.next_entry()? {
                out.push(entry);
            }
            Ok(out)
        }
    }
    d.deserialize_map(Ordered)
}

/// What flows through a branch of the prescribed table.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Drive {
    /// A ventricle's half-sine ejection.
    Ejection,
    /// This share of the cardiac output, steady.
    Steady(f64),
}

/// The loop in SI: what the core's `ClosedLoopSpec` takes (`compartments`, `branches`,
/// `binding`) and what its caller needs to build the heart and the tree around it.
#[derive(Debug, Clone, Serialize)]
pub struct Layout {
    pub compartments: Vec<Value>,
    pub branches: Vec<Value>,
    pub binding: Value,
    /// Every organ bed's resistance (Pa s/m³): the mean arterial pressure over its flow.
    pub organ_resistances: Vec<f64>,
    /// The blood's O2 solubility in the network model's oxygen unit (mol m⁻³ mmHg⁻¹).
    pub solubility_per_mmhg: f64,
    /// The cardiac output (m³/s).
    pub cardiac_output: f64,
    #[serde(skip)]
    drives: Vec<Drive>,
}

impl LoopParams {
    pub fn from_json(json: &str) -> Result<Self> {
        serde_json::from_str(json).map_err(|e| Error::model("closed loop", e.to_string()))
    }

    pub fn has_tree(&self) -> bool {
        self.arteries == "tree"
    }

    /// The cardiac output in m³/s.
    fn flow(&self) -> f64 {
        self.cardiac_output * 1e-3 / 60.0
    }

    /// The compartments (flow order), branches and binding in SI.
    pub fn layout(&self) -> Layout {
        let (p, b) = (&self.pools, &self.blood);
        let tree = self.has_tree();
        let mut comps: Vec<(&str, f64)> = vec![("left_heart", p.left_heart)];
        if !tree {
            comps.push(("arteries", p.arteries));
        }
        comps.extend(self.organs.iter().map(|(k, o)| (k.as_str(), o.volume)));
        comps.extend([
            ("veins", p.veins),
            ("right_heart", p.right_heart),
            ("pulmonary_arteries", p.pulmonary_arteries),
            ("pulmonary_veins", p.pulmonary_veins),
        ]);
        let idx = |name: &str| comps.iter().position(|(n, _)| *n == name).unwrap_or(0);
        let compartments = comps
            .iter()
            .map(|&(name, vol)| self.compartment(name, vol))
            .collect();
        let shunt = self.lungs.shunt_fraction;
        let mut br: Vec<(String, &str, &str, Drive)> = Vec::new();
        if !tree {
            br.push((
                String::from("ejection_left"),
                "left_heart",
                "arteries",
                Drive::Ejection,
            ));
            for (k, o) in &self.organs {
                br.push((
                    format!("{k}_in"),
                    "arteries",
                    k.as_str(),
                    Drive::Steady(o.flow_fraction),
                ));
            }
        }
        for (k, o) in &self.organs {
            br.push((
                format!("{k}_out"),
                k.as_str(),
                "veins",
                Drive::Steady(o.flow_fraction),
            ));
        }
        br.extend([
            (
                String::from("venous_return"),
                "veins",
                "right_heart",
                Drive::Steady(1.0),
            ),
            (
                String::from("ejection_right"),
                "right_heart",
                "pulmonary_arteries",
                Drive::Ejection,
            ),
            (
                String::from("pulmonary_capillaries"),
                "pulmonary_arteries",
                "pulmonary_veins",
                Drive::Steady(1.0 - shunt),
            ),
            (
                String::from("shunt"),
                "pulmonary_arteries",
                "pulmonary_veins",
                Drive::Steady(shunt),
            ),
            (
                String::from("filling_left"),
                "pulmonary_veins",
                "left_heart",
                Drive::Steady(1.0),
            ),
        ]);
        let lungs = json!({
            "alveolar_po2": self.lungs.alveolar_po2 * MMHG,
            "diffusing_capacity": self.lungs.diffusing_capacity / 60.0 * ML_O2 / MMHG,
        });
        let branches = br
            .iter()
            .map(|(n, f, t, _)| {
                let (f, t): (&str, &str) = (f, t);
                let mut v = json!({"name": n, "from": idx(f), "to": idx(t)});
                if n == "pulmonary_capillaries" {
                    v["lungs"] = lungs.clone();
                }
                v
            })
            .collect();
        let r_sys = MEAN_ARTERIAL_MMHG * MMHG / self.flow();
        Layout {
            compartments,
            branches,
            binding: json!({
                "kind": "hill",
                "solubility": b.solubility * 10.0 * 1e3 * ML_O2 / MMHG,
                "p50": b.p50 * MMHG,
                "n": b.hill_n,
                "capacity": b.hemoglobin * b.hufner * 1e3 * ML_O2,
            }),
            organ_resistances: self
                .organs
                .iter()
                .map(|(_, o)| r_sys / o.flow_fraction)
                .collect(),
            solubility_per_mmhg: b.solubility * 10.0 * 1e3 * ML_O2,
            cardiac_output: self.flow(),
            drives: br.iter().map(|branch| branch.3).collect(),
        }
    }

    /// One compartment: volume (m³), start PO2 (Pa: 95 mmHg on the oxygenated side, 40 on
    /// the other), an organ's Michaelis–Menten consumption (mol/s, Pa).
    fn compartment(&self, name: &str, volume: f64) -> Value {
        let oxygenated = matches!(name, "left_heart" | "arteries" | "pulmonary_veins");
        let po2_mmhg = if oxygenated { 95.0 } else { 40.0 };
        let mut c = json!({"name": name, "volume": volume * 1e-3, "initial_po2": po2_mmhg * MMHG});
        if let Some((_, o)) = self.organs.iter().find(|(k, _)| k == name) {
            c["consumption"] = json!({"kind": "michaelis-menten", "vmax": o.vo2 / 60.0 * ML_O2,
                                      "km": self.km * MMHG});
        }
        c
    }

    /// The prescribed flows (m³/s, steps × branches, row-major) for each step of one cycle:
    /// half-sine ejections of both ventricles over `ejection_time`, scaled so that their
    /// discrete cycle mean is the cardiac output exactly (periodic chamber volumes, which the
    /// loop checks), and steady shares of the cardiac output elsewhere.
    pub fn flow_table(&self, layout: &Layout) -> Result<(Vec<f64>, usize)> {
        let err = |m: String| Error::model("closed loop", m);
        let steps = (self.period / self.dt).round();
        if steps.is_nan()
            || steps < 1.0
            || ((steps * self.dt - self.period).abs() > 1e-12 * self.period)
        {
            return Err(err(format!(
                "period {} s is not a whole number of steps dt = {} s",
                self.period, self.dt
            )));
        }
        let total: f64 = self.organs.iter().map(|(_, o)| o.flow_fraction).sum();
        if (total - 1.0).abs() > 1e-9 * total.abs().max(1.0) {
            return Err(err(format!("organ flow fractions sum to {total}, not 1")));
        }
        let ejection_time = self
            .ejection_time
            .ok_or_else(|| err("the prescribed flow table needs 'ejection_time' (s)".into()))?;
        let steps = steps as usize;
        let q = self.flow();
        let shape: Vec<f64> = (0..steps)
            .map(|s| {
                let t = (s as f64 + 0.5) * self.dt;
                if t < ejection_time {
                    (std::f64::consts::PI * t / ejection_time).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let mean = shape.iter().sum::<f64>() / steps as f64;
        let mut table = Vec::with_capacity(steps * layout.drives.len());
        for s in shape {
            table.extend(layout.drives.iter().map(|d| match *d {
                Drive::Ejection => q * s / mean,
                Drive::Steady(f) => q * f,
            }));
        }
        Ok((table, steps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(arteries: &str) -> LoopParams {
        LoopParams::from_json(&format!(
            r#"{{"period": 0.8, "dt": 1e-3, "cardiac_output": 6.0, "ejection_time": 0.3,
               "blood": {{"solubility": 0.003, "hemoglobin": 150.0, "hufner": 1.34,
                          "p50": 26.8, "hill_n": 2.7}},
               "lungs": {{"alveolar_po2": 100.0, "diffusing_capacity": 21.0,
                          "shunt_fraction": 0.02}},
               "pools": {{"left_heart": 0.15, "arteries": 0.75, "veins": 3.0,
                          "right_heart": 0.15, "pulmonary_arteries": 0.15,
                          "pulmonary_veins": 0.3}},
               "km": 1.0, "arteries": "{arteries}",
               "organs": {{"muscle": {{"flow_fraction": 0.75, "vo2": 50.0, "volume": 0.2}},
                           "brain": {{"flow_fraction": 0.25, "vo2": 50.0, "volume": 0.075}}}},
               "heart": "anything else is read elsewhere"}}"#
        ))
        .unwrap()
    }

    /// Every compartment's net inflow over the prescribed cycle is zero (blood is conserved),
    /// the ejection's cycle mean is the cardiac output, and the organs keep the file's order.
    #[test]
    fn prescribed_table_conserves_every_compartment_and_pumps_the_cardiac_output() {
        let p = params("pool");
        let lay = p.layout();
        let names: Vec<_> = lay.compartments.iter().map(|c| c["name"].clone()).collect();
        assert_eq!(names[2], "muscle");
        assert_eq!(names[3], "brain");
        let (table, steps) = p.flow_table(&lay).unwrap();
        assert_eq!(steps, 800);
        let nb = lay.branches.len();
        let mut net = vec![0.0; lay.compartments.len()];
        for row in table.chunks(nb) {
            for (b, q) in lay.branches.iter().zip(row) {
                net[b["from"].as_u64().unwrap() as usize] -= q;
                net[b["to"].as_u64().unwrap() as usize] += q;
            }
        }
        let co = 6.0e-3 / 60.0;
        for n in net {
            assert!(n.abs() <= 1e-12 * co * steps as f64, "{n}");
        }
        let ejected: f64 = table.chunks(nb).map(|r| r[0]).sum::<f64>() / steps as f64;
        assert!((ejected - co).abs() <= 1e-14 * co);
        // 93 mmHg over each bed's share of the output
        assert!((lay.organ_resistances[1] - 93.0 * 133.322368 / (0.25 * co)).abs() < 1e-3);
    }

    #[test]
    fn tree_has_no_arterial_pool_and_bad_tables_are_named() {
        let lay = params("tree").layout();
        assert!(lay.compartments.iter().all(|c| c["name"] != "arteries"));
        assert_eq!(lay.branches.len(), 2 + 5);
        let mut p = params("pool");
        p.dt = 0.3;
        let e = p.flow_table(&p.layout()).unwrap_err().to_string();
        assert!(
            e.contains("period 0.8 s is not a whole number of steps dt = 0.3 s"),
            "{e}"
        );
        let mut p = params("pool");
        p.organs[0].1.flow_fraction = 0.5;
        let e = p.flow_table(&p.layout()).unwrap_err().to_string();
        assert!(e.contains("organ flow fractions sum to 0.75, not 1"), "{e}");
    }
}
