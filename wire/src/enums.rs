//! One table per wire enum. The `wire_enum!` macro turns
//! the rows `"name" => Variant` of an engine enum into a [`WireEnum`]
//! impl: both conversions as exhaustive matches (a variant added to either
//! side breaks the build here until its row exists), the names as the
//! scene file spells them, and the "use a, b or c" text of every error, so
//! no enum is spelled by hand anywhere else.
//!
//! The engine and proto variants share their names (prost strips the
//! proto's `KERNEL_KIND_` prefixes); each proto enum's 0 is `Unspecified`.

use crate::error::Result;
use crate::error::WireError;

/// An engine enum that crosses the protocol as the proto enum `Proto`.
pub trait WireEnum: Copy + Sized + 'static {
    /// The generated proto enum.
    type Proto: Copy + Into<i32> + TryFrom<i32>;
    /// What a value is, in error messages ("kernel", "wall model").
    const WHAT: &'static str;
    /// Every variant's name as scene files spell it, in table order.
    const NAMES: &'static [&'static str];

    /// The proto value of an engine value.
    fn to_proto(self) -> Self::Proto;
    /// The engine value of a proto value; `None` for `Unspecified`.
    fn from_proto(proto: Self::Proto) -> Option<Self>;
    /// The variant's name as scene files spell it.
    fn name(self) -> &'static str;
    /// The variant of a name as scene files spell it.
    fn from_name(name: &str) -> Option<Self>;

    /// The number a message field holds for this value.
    fn to_i32(self) -> i32 {
        self.to_proto().into()
    }

    /// The engine value of a message field's number; `None` for
    /// `Unspecified` and for numbers this build does not know.
    fn from_i32(value: i32) -> Option<Self> {
        Self::Proto::try_from(value).ok().and_then(Self::from_proto)
    }

    /// The names for an error message: `a, b or c`.
    fn choices() -> String {
        match Self::NAMES {
            [] => String::new(),
            [only] => (*only).to_owned(),
            [rest @ .., last] => format!("{} or {last}", rest.join(", ")),
        }
    }
}

/// Implements [`WireEnum`] for an engine enum from its rows:
///
/// ```text
/// wire_enum! {
///     /// Doc of the table.
///     SolverKind <-> SolverKind, "solver" {
///         "wcsph" => Wcsph,
///         "dfsph" => Dfsph,
///     }
/// }
/// ```
///
/// The engine type must be in scope; the proto type is named in
/// `meshless_proto::v1`.
macro_rules! wire_enum {
    (
        $(#[$doc:meta])*
        $engine:ident <-> $proto:ident, $what:literal {
            $($name:literal => $variant:ident),+ $(,)?
        }
    ) => {
        $(#[$doc])*
        impl $crate::enums::WireEnum for $engine {
            type Proto = ::meshless_proto::v1::$proto;
            const WHAT: &'static str = $what;
            const NAMES: &'static [&'static str] = &[$($name),+];

            fn to_proto(self) -> Self::Proto {
                match self {
                    $($engine::$variant => ::meshless_proto::v1::$proto::$variant,)+
                }
            }

            fn from_proto(proto: Self::Proto) -> Option<Self> {
                match proto {
                    ::meshless_proto::v1::$proto::Unspecified => None,
                    $(::meshless_proto::v1::$proto::$variant => Some($engine::$variant),)+
                }
            }

            fn name(self) -> &'static str {
                match self {
                    $($engine::$variant => $name,)+
                }
            }

            fn from_name(name: &str) -> Option<Self> {
                match name {
                    $($name => Some($engine::$variant),)+
                    _ => None,
                }
            }
        }
    };
}
pub(crate) use wire_enum;

/// The error of a number that names no variant: `unknown {what} {shown};
/// use a, b or c`.
fn unknown<E: WireEnum>(shown: impl std::fmt::Display, field: &str) -> WireError {
    WireError::new(
        field,
        format!("unknown {} {shown}; use {}", E::WHAT, E::choices()),
    )
}

/// A field that must name a variant (a repeated field's entry, or an
/// `optional` one once set): `Unspecified` and unknown numbers are refused.
pub(crate) fn required_enum<E: WireEnum>(value: i32, field: &str) -> Result<E> {
    E::from_i32(value).ok_or_else(|| unknown::<E>(value, field))
}

/// A plain proto3 enum field, whose `Unspecified` (what a client that
/// never set it sends) means `default`; unknown numbers are refused.
pub(crate) fn enum_or<E: WireEnum>(value: i32, default: E, field: &str) -> Result<E> {
    match E::Proto::try_from(value) {
        Ok(proto) => Ok(E::from_proto(proto).unwrap_or(default)),
        Err(_) => Err(unknown::<E>(value, field)),
    }
}

/// An `optional` enum field: unset means `default`; a set value must name
/// a variant. The error shows the value as the service always has, as
/// `Some(n)`.
pub(crate) fn optional_enum<E: WireEnum>(value: Option<i32>, default: E, field: &str) -> Result<E> {
    match value {
        None => Ok(default),
        Some(number) => {
            E::from_i32(number).ok_or_else(|| unknown::<E>(format_args!("{value:?}"), field))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meshless_engine::FieldKind;
    use meshless_engine::approx::KernelKind;
    use meshless_engine::approx::mls::Order;
    use meshless_engine::design::Quadrature;
    use meshless_engine::fluid::ViscosityModel;
    use meshless_engine::scene::{IntegratorKind, MotionKind, SlipKind, SolverKind, WallModel};
    use meshless_engine::solid::embedded::EmbeddingMethod;
    use meshless_engine::solid::{Hyperelastic, ImplicitScheme, LinearSolver};

    /// Every name of `E`'s table is the scene file's spelling of its
    /// variant, and every variant survives both conversions.
    fn check<E>()
    where
        E: WireEnum + PartialEq + std::fmt::Debug + serde::Serialize,
    {
        for &name in E::NAMES {
            let value = E::from_name(name).unwrap_or_else(|| panic!("{name} is in the table"));
            assert_eq!(value.name(), name);
            assert_eq!(
                serde_json::to_value(value).expect("serialises"),
                serde_json::Value::String(name.to_owned()),
                "{} {name}: the scene file spells it otherwise",
                E::WHAT
            );
            assert_eq!(E::from_proto(value.to_proto()), Some(value));
            assert_eq!(E::from_i32(value.to_i32()), Some(value));
        }
        assert_eq!(E::from_i32(0), None, "0 is unspecified");
        assert_eq!(E::from_name("no such name"), None);
    }

    #[test]
    fn every_table_agrees_with_the_scene_files_and_round_trips() {
        check::<FieldKind>();
        check::<KernelKind>();
        check::<WallModel>();
        check::<ViscosityModel>();
        check::<SolverKind>();
        check::<MotionKind>();
        check::<SlipKind>();
        check::<Order>();
        check::<IntegratorKind>();
        check::<Hyperelastic>();
        check::<EmbeddingMethod>();
        check::<meshless_engine::solid::fracture::CrackCriterion>();
        check::<LinearSolver>();
        check::<ImplicitScheme>();
        check::<Quadrature>();
    }

    /// The three shapes of enum field refuse what they should, with the
    /// texts clients have always seen.
    #[test]
    fn errors_list_the_choices() {
        assert_eq!(SolverKind::choices(), "wcsph or dfsph");
        assert_eq!(
            FieldKind::choices(),
            "position, velocity, density, pressure, mass, volume, kinetic_energy, elastic_energy, \
             id or fragment"
        );
        let err = required_enum::<FieldKind>(0, "output.fields[0]").expect_err("unspecified");
        assert_eq!(
            err.to_string(),
            "output.fields[0]: unknown field kind 0; use position, velocity, density, pressure, \
             mass, volume, kinetic_energy, elastic_energy, id or fragment"
        );
        assert_eq!(
            enum_or(0, MotionKind::Dynamic, "motion"),
            Ok(MotionKind::Dynamic)
        );
        let err = enum_or(77, MotionKind::Dynamic, "motion").expect_err("unknown");
        assert_eq!(
            err.to_string(),
            "motion: unknown motion 77; use static, kinematic or dynamic"
        );
        assert_eq!(
            optional_enum(None, WallModel::Reflect, "walls"),
            Ok(WallModel::Reflect)
        );
        let err = optional_enum(Some(0), WallModel::Reflect, "walls").expect_err("unspecified");
        assert_eq!(
            err.to_string(),
            "walls: unknown wall model Some(0); use solid or reflect"
        );
    }
}
