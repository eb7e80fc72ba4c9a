//! Vector fields a scene writes as formulas: an initial velocity field
//! over the fluid's particles, a body force over space. Each component is
//! an arithmetic expression in the position `x`, `y`, `z` (m), parsed and
//! evaluated in f64 by exmex: numbers (`2`, `0.5`, `.5`, and in
//! scientific notation `1e-3`, `2.5E+4`), `+ - * / ^`, parentheses,
//! `sin`, `cos`, `tan`, `exp`, `log`/`ln`, `sqrt`, `abs`, `tanh` and the
//! others exmex knows, the constants `PI`/`π`, `TAU` and `E`.
//!
//! exmex's own number literals have no exponent (`1e-3` would read as
//! `1`, then a variable `e`), so components are parsed with
//! [`Literal`], which takes one.
//!
//! A scene names a field instead of listing a velocity per particle, so a
//! 31k-particle drop in a vortex is three short lines, not 3 MB.
//!
//! Text comes from clients, so a component is limited to
//! [`MAX_EXPRESSION_CHARS`] characters before it is parsed (exmex parses
//! iteratively, without recursion, and evaluation is one pass over the
//! flattened expression), and its variables must be among `x`, `y`, `z`.

use crate::math::{Brief, Real, Vector};
use exmex::prelude::*;
use exmex::{FloatOpsFactory, MatchLiteral};
use std::fmt;

/// A parsed component: exmex's float operators, [`Literal`] numbers.
type Formula = FlatEx<Real, FloatOpsFactory<Real>, Literal>;

/// What a formula may hold, for the message that refuses one.
const ALLOWED: &str = "use numbers (2, 0.5, 1e-3, 2.5E+4), x, y and z, + - * / ^, \
                       parentheses, functions such as sin, cos, exp, sqrt and abs, and PI";

/// Longest component text, in characters.
pub const MAX_EXPRESSION_CHARS: usize = 500;

/// Longest piece of exmex's message an error repeats: it quotes the
/// formula, which is the client's text.
const MAX_ERROR_CHARS: usize = 48;

/// The variables a component may use, in the order of [`Vector`]'s axes.
const VARIABLES: [&str; 3] = ["x", "y", "z"];

/// Why a component could not be made a formula.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExpressionError(String);

impl fmt::Display for ExpressionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ExpressionError {}

/// Number literals with an optional exponent: digits with an optional
/// fraction (`2`, `2.`, `2.5`, `.5`), then `e` or `E`, an optional sign
/// and digits. An `e` not followed by digits is left to the parser (a
/// variable or `exp` after a number is its business).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Literal;

impl MatchLiteral for Literal {
    fn is_literal(text: &str) -> Option<&str> {
        let bytes = text.as_bytes();
        let digits = |from: usize| {
            bytes[from..]
                .iter()
                .take_while(|b| b.is_ascii_digit())
                .count()
        };
        let whole = digits(0);
        let mut end = whole;
        let mut fraction = 0;
        if bytes.get(end) == Some(&b'.') {
            fraction = digits(end + 1);
            end += 1 + fraction;
        }
        // At least one digit: a lone "." is no number.
        if whole + fraction == 0 {
            return None;
        }
        if let Some(b'e' | b'E') = bytes.get(end) {
            let sign = usize::from(matches!(bytes.get(end + 1), Some(b'+' | b'-')));
            let exponent = digits(end + 1 + sign);
            if exponent > 0 {
                end += 1 + sign + exponent;
            }
        }
        // All ASCII up to `end`, so a character boundary.
        Some(&text[..end])
    }
}

/// One parsed component, with the axis each of its variables reads.
#[derive(Debug, Clone)]
struct Component {
    expression: Formula,
    /// For each variable of `expression` (in its alphabetical order), the
    /// axis whose coordinate it is.
    axes: Vec<usize>,
    /// The value of a formula without variables, computed once: a uniform
    /// body force costs nothing per particle.
    constant: Option<Real>,
}

impl Component {
    fn parse(text: &str) -> Result<Self, ExpressionError> {
        let chars = text.chars().count();
        if chars > MAX_EXPRESSION_CHARS {
            return Err(ExpressionError(format!(
                "is {chars} characters long; keep a component to {MAX_EXPRESSION_CHARS}"
            )));
        }
        let expression = Formula::parse(text).map_err(|e| {
            // exmex quotes the tokens around the fault, which are the
            // client's text: keep a prefix too short to echo it (the
            // `scene_toml` fuzz target found 200 characters repeating a
            // token of the input).
            let message = e.to_string();
            let mut short: String = message.chars().take(MAX_ERROR_CHARS).collect();
            if message.chars().count() > MAX_ERROR_CHARS {
                short.push('…');
            }
            ExpressionError(format!(
                "is not a formula in x, y and z; {ALLOWED} (the parser said: {short})"
            ))
        })?;
        let axes = expression
            .var_names()
            .iter()
            .map(|name| {
                VARIABLES.iter().position(|v| v == name).ok_or_else(|| {
                    let shown: String = name.chars().take(40).collect();
                    ExpressionError(format!(
                        "uses the variable `{shown}`; a field may use only x, y and z \
                         ({ALLOWED})"
                    ))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        let constant = axes
            .is_empty()
            .then(|| expression.eval(&[]).unwrap_or(Real::NAN));
        Ok(Self {
            expression,
            axes,
            constant,
        })
    }

    /// The component at `at`, without allocating: it runs for every
    /// particle at every sub-step of a body force.
    fn eval(&self, at: &Vector) -> Real {
        if let Some(c) = self.constant {
            return c;
        }
        let mut values = [0.0; 3];
        for (value, &a) in values.iter_mut().zip(&self.axes) {
            *value = at[a];
        }
        // Every variable was given, so evaluation cannot fail for want of
        // one; a domain error is NaN like any other non-finite value,
        // which the callers check.
        self.expression
            .eval(&values[..self.axes.len()])
            .unwrap_or(Real::NAN)
    }
}

/// A vector field of three formulas in `x`, `y`, `z`.
#[derive(Debug, Clone)]
pub struct VectorField {
    components: [Component; 3],
}

impl VectorField {
    /// Parses the three components.
    ///
    /// # Errors
    /// The first component that is too long, unreadable or uses another
    /// variable, with its index.
    pub fn parse(texts: &[String; 3]) -> Result<Self, (usize, ExpressionError)> {
        let parse = |a: usize| Component::parse(&texts[a]).map_err(|e| (a, e));
        Ok(Self {
            components: [parse(0)?, parse(1)?, parse(2)?],
        })
    }

    /// The field at `at`; non-finite where a formula is (a division by
    /// zero, `sqrt` of a negative number).
    pub fn eval(&self, at: &Vector) -> Vector {
        Vector::from_fn(|a, _| self.components[a].eval(at))
    }

    /// The first of `points` where the field is not finite, if any; one
    /// point at a time, so the caller bounds the work by bounding the
    /// points.
    pub fn first_non_finite(&self, points: impl IntoIterator<Item = Vector>) -> Option<NonFinite> {
        points
            .into_iter()
            .enumerate()
            .find(|(_, x)| !self.eval(x).iter().all(|c| c.is_finite()))
            .map(|(index, at)| NonFinite { index, at })
    }
}

/// Where a field is not finite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NonFinite {
    /// The point's index.
    pub index: usize,
    /// The point.
    pub at: Vector,
}

impl fmt::Display for NonFinite {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "is not finite at ({}, {}, {})",
            Brief(self.at.x),
            Brief(self.at.y),
            Brief(self.at.z)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(texts: [&str; 3]) -> Result<VectorField, (usize, ExpressionError)> {
        VectorField::parse(&texts.map(str::to_owned))
    }

    /// A Taylor–Green field evaluates to its closed form, constants and
    /// functions included, whatever subset of the variables a component
    /// uses.
    #[test]
    fn formulas_evaluate_to_their_closed_form() {
        let tg = field([
            "-0.1*cos(2*PI*x)*sin(2*PI*y)",
            "0.1*sin(2*PI*x)*cos(2*PI*y)",
            "z^2 + 1/2",
        ])
        .expect("parses");
        let at = Vector::new(0.3, 0.7, 2.0);
        let k = 2.0 * std::f64::consts::PI;
        let v = tg.eval(&at);
        assert!((v.x + 0.1 * (k * 0.3).cos() * (k * 0.7).sin()).abs() < 1e-15);
        assert!((v.y - 0.1 * (k * 0.3).sin() * (k * 0.7).cos()).abs() < 1e-15);
        assert_eq!(v.z, 4.5, "1/2 is a real division");
        let constant = field(["1.5", "0", "-2"]).expect("parses");
        assert_eq!(constant.eval(&at), Vector::new(1.5, 0.0, -2.0));
    }

    /// Numbers in scientific notation are numbers (exmex's own literals
    /// stop at the `e`): with either case of `e`, either sign or none, a
    /// fraction or not, beside variables and the constant `E`.
    #[test]
    fn scientific_notation_reads_as_numbers() {
        let at = Vector::new(2.0, 3.0, 0.5);
        let v = field(["1e-3*x", "2.5E+4 + y", "1e3*z - .5e1"])
            .expect("scientific notation parses")
            .eval(&at);
        assert_eq!(v, Vector::new(1e-3 * 2.0, 2.5e4 + 3.0, 1e3 * 0.5 - 5.0));
        let v = field(["-1E-2", "2.e2", "E*x + 3e0"])
            .expect("parses")
            .eval(&at);
        assert_eq!(v.x, -1e-2);
        assert_eq!(v.y, 200.0);
        assert!((v.z - (std::f64::consts::E * 2.0 + 3.0)).abs() < 1e-12);
        for (text, literal) in [
            ("1e-3*x", Some("1e-3")),
            ("2.5E+4", Some("2.5E+4")),
            ("1e3", Some("1e3")),
            ("2exp(x)", Some("2")),
            ("3e+x", Some("3")),
            (".", None),
            ("x", None),
        ] {
            assert_eq!(Literal::is_literal(text), literal, "{text}");
        }
    }

    /// Bad text is refused with the component named: unknown variables,
    /// syntax, length; a formula that is infinite somewhere is found at
    /// its point.
    #[test]
    fn bad_formulas_are_refused_with_the_reason() {
        let (a, e) = field(["x", "t*2", "0"]).expect_err("t is not a variable here");
        assert_eq!(a, 1);
        assert!(e.to_string().contains("`t`"), "{e}");
        let (a, e) = field(["x +* (", "0", "0"]).expect_err("syntax");
        assert_eq!(a, 0);
        assert!(e.to_string().contains("formula"), "{e}");
        assert!(
            e.to_string().contains("1e-3") && e.to_string().contains("x, y and z"),
            "the message says what a formula may hold: {e}"
        );
        let echo = format!("0.1*{}sin(2*PI*y)", "b".repeat(300));
        let (_, e) = VectorField::parse(&[echo, "0".into(), "0".into()]).expect_err("syntax");
        assert!(!e.to_string().contains(&"b".repeat(49)), "{e}");
        let long = "x+".repeat(400) + "x";
        let (_, e) = VectorField::parse(&[long, "0".into(), "0".into()]).expect_err("too long");
        assert!(e.to_string().contains("500"), "{e}");
        let pole = field(["1/(x - 0.5)", "0", "0"]).expect("parses");
        let points = [Vector::new(0.25, 0.0, 0.0), Vector::new(0.5, 0.0, 0.0)];
        let bad = pole.first_non_finite(points).expect("a pole");
        assert_eq!(bad.index, 1);
        assert!(bad.to_string().contains("(0.5, 0, 0)"), "{bad}");
    }
}
