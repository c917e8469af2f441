//! The function a carrier of unexplained structure fitted ([`Carrier::shape`]) in the units a
//! person reads: its variable with its unit, and the torque (or voltage) it leaves
//! unexplained. One conversion serves `diagnose --json`, the text's shape line and the
//! report's charts.
use crate::diagnose::candidates::Equation;
use crate::diagnose::carriers::Carrier;
use crate::log::{MotorLog, Plant};
use crate::model::Model;
use serde::Serialize;

/// A carrier's function with its axes named and in units.
#[derive(Debug, Clone, Serialize)]
pub struct Drawn {
    /// Values of the variable, in `x_unit`.
    pub x: Vec<f64>,
    /// The residual's function at `x`, in `y_unit`.
    pub y: Vec<f64>,
    /// For `time`: the part that acts in the direction of motion (`y`: the part that does
    /// not).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub y_signed: Option<Vec<f64>>,
    /// What `x` is, e.g. `speed ω`.
    pub x_label: String,
    pub x_unit: String,
    /// What `y` is, e.g. `unexplained torque`.
    pub y_label: String,
    pub y_unit: String,
}

/// What the variable is and its unit, on `log` (a linear axis reads metres, a torque plant's
/// current is its command).
fn variable_axis(variable: &str, model: &Model, log: &MotorLog) -> (&'static str, String) {
    let linear = log.is_linear();
    let rad = |u: &str| crate::ident::relabel_unit(u, &torque_unit(model, log), linear);
    match variable {
        "theta" => ("angle θ", rad("rad")),
        "omega" => ("speed ω", rad("rad/s")),
        "acceleration" => ("acceleration", rad("rad/s²")),
        "current" if model.plant == Plant::Torque => ("torque command u", torque_unit(model, log)),
        "current" => ("current I", "A".into()),
        "time" => ("time t", "s".into()),
        "reversal" => ("time since the last reversal", "s".into()),
        "frequency" => ("frequency", "Hz".into()),
        _ => ("value", String::new()),
    }
}

/// The unit of a torque on this model and log ([`crate::ident::torque_unit`]).
fn torque_unit(model: &Model, log: &MotorLog) -> String {
    crate::ident::torque_unit(model.plant, std::slice::from_ref(log))
}

/// `c`'s function in units: the torque equation of a voltage plant is written in volts, so
/// its shape is turned into a torque with the model's K_t/R; the voltage equation's stays in
/// volts; a torque plant's is in its input's unit.
pub fn drawn(c: &Carrier, model: &Model, log: &MotorLog) -> Drawn {
    let (x_label, x_unit) = variable_axis(c.variable, model, log);
    let (factor, y_label, y_unit) = match (c.equation, model.plant) {
        (Equation::Electrical, _) => (1.0, "unexplained voltage", "V".to_string()),
        (Equation::Mechanical, Plant::Torque) => {
            (1.0, "unexplained torque", torque_unit(model, log))
        }
        (Equation::Mechanical, Plant::Voltage) => {
            let (kt, r) = (model.motor.kt, model.motor.r);
            if kt > 0.0 && r > 0.0 && (kt / r).is_finite() {
                (kt / r, "unexplained torque", torque_unit(model, log))
            } else {
                (1.0, "unexplained torque (in volts)", "V".to_string())
            }
        }
    };
    let y_label = match c.variable {
        "frequency" => format!("{y_label}, amplitude"),
        "reversal" => format!("{y_label} in the direction of motion"),
        _ => y_label.to_string(),
    };
    let scale = |v: &[f64]| v.iter().map(|y| y * factor).collect::<Vec<f64>>();
    Drawn {
        x: c.shape.x.clone(),
        y: scale(&c.shape.y),
        y_signed: c.shape.y_signed.as_deref().map(scale),
        x_label: x_label.to_string(),
        x_unit,
        y_label,
        y_unit,
    }
}

impl Drawn {
    /// Axis titles with units, e.g. `speed ω [rad/s]`.
    pub fn axis_titles(&self) -> (String, String) {
        let t = |l: &str, u: &str| {
            if u.is_empty() {
                l.to_string()
            } else {
                format!("{l} [{u}]")
            }
        };
        (
            t(&self.x_label, &self.x_unit),
            t(&self.y_label, &self.y_unit),
        )
    }

    /// One line: where the function is largest and smallest (for `frequency`: where the band
    /// peaks). Empty when there is nothing to draw.
    pub fn summary(&self) -> String {
        let at = |pick: fn(f64, f64) -> bool| -> Option<(f64, f64)> {
            self.x
                .iter()
                .zip(&self.y)
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .fold(None, |best: Option<(f64, f64)>, (&x, &y)| match best {
                    Some((_, b)) if !pick(y, b) => best,
                    _ => Some((x, y)),
                })
        };
        let (Some(hi), Some(lo)) = (at(|a, b| a > b), at(|a, b| a < b)) else {
            return String::new();
        };
        let (xu, yu) = (&self.x_unit, &self.y_unit);
        if self.x_label == "frequency" {
            return format!(
                "shape: peaks at {:.3} Hz ({:.3e} {yu} amplitude)",
                hi.0, hi.1
            );
        }
        let mut s = format!(
            "shape over {}: largest {:+.3e} {yu} at {:.4} {xu}, smallest {:+.3e} {yu} at {:.4} {xu}",
            self.x_label, hi.1, hi.0, lo.1, lo.0
        );
        if let Some(ys) = &self.y_signed {
            let m = ys.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            s.push_str(&format!(
                "; with the direction of motion up to {m:.3e} {yu}"
            ));
        }
        s
    }

    /// The series to draw: the function, and for `time` its part with the direction.
    pub fn series(&self) -> Vec<(&str, &[f64], &[f64])> {
        let mut v: Vec<(&str, &[f64], &[f64])> = vec![(
            if self.y_signed.is_some() {
                "either direction"
            } else {
                "function"
            },
            &self.x,
            &self.y,
        )];
        if let Some(ys) = &self.y_signed {
            v.push(("with the direction of motion", &self.x, ys));
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::carriers::Shape;

    fn carrier(variable: &'static str, equation: Equation, shape: Shape) -> Carrier {
        Carrier {
            variable,
            share: 0.2,
            p_value: 1e-9,
            explanation: String::new(),
            equation,
            shape,
            hz: None,
            spec: None,
        }
    }

    #[test]
    fn a_torque_shape_of_a_voltage_plant_is_turned_into_newton_metres() {
        let model = Model::new(crate::model::ModelKind::Lugre, Plant::Voltage, 1e-3);
        let log = MotorLog::default();
        let shape = Shape {
            x: vec![-10.0, 0.0, 10.0],
            y: vec![-1.0, 0.5, 2.0],
            y_signed: None,
        };
        let d = drawn(
            &carrier("omega", Equation::Mechanical, shape.clone()),
            &model,
            &log,
        );
        let k = model.motor.kt / model.motor.r;
        assert_eq!(d.y_unit, "N·m");
        for (a, b) in d.y.iter().zip(&shape.y) {
            // One multiplication by K_t/R: rounding only.
            assert!((a - b * k).abs() < 1e-12);
        }
        assert_eq!(d.axis_titles().0, "speed ω [rad/s]");
        let s = d.summary();
        assert!(
            s.contains("largest") && s.contains("at 10.0000 rad/s"),
            "{s}"
        );
        // The voltage equation keeps its volts.
        let e = drawn(
            &carrier("current", Equation::Electrical, shape),
            &model,
            &log,
        );
        assert_eq!((e.y_unit.as_str(), e.y[2]), ("V", 2.0));
        assert_eq!(e.axis_titles().0, "current I [A]");
    }
}
