//! Choices made by name (methods, solvers, stopping rules, boundaries,
//! sheet scales): one list of values and their names, for configuration
//! files, front ends and reports alike.

/// An enumeration whose values have stable names.
pub trait Named: Copy + Sized + Send + Sync + 'static {
    /// Every value, in the order to list them.
    const ALL: &'static [Self];

    /// The value's name (lower case, words joined by `-`).
    fn name(self) -> &'static str;

    /// The value called `name`, if any.
    fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|v| v.name() == name)
    }

    /// Every name, in [`Named::ALL`]'s order.
    fn names() -> impl Iterator<Item = &'static str> {
        Self::ALL.iter().map(|v| v.name())
    }
}

/// A command-line value parser for a [`Named`] choice: its names are the
/// possible values.
#[cfg(feature = "cli")]
pub fn choice<T: Named + Clone>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(T::names())
        .map(|name| T::from_name(&name).expect("clap checked the name"))
}

/// Implements [`Named`] for a fieldless enum from `Variant => "name"` pairs.
macro_rules! named {
    ($t:ty { $($v:ident => $n:literal),+ $(,)? }) => {
        impl $crate::named::Named for $t {
            const ALL: &'static [Self] = &[$(<$t>::$v),+];
            fn name(self) -> &'static str {
                match self {
                    $(<$t>::$v => $n),+
                }
            }
        }
    };
}
pub(crate) use named;

named!(crate::physics::Sampling {
    Integrated => "integrated",
    Point => "point",
});

#[cfg(test)]
mod tests {
    use super::Named;
    use crate::formats::png::SheetScale;
    use crate::forward::Boundary;
    use crate::reconstruct::admm_lbfgs::PnpStop;
    use crate::reconstruct::method::{Method, RlStop, Solver};

    fn round_trips<T: Named + PartialEq + std::fmt::Debug>() {
        let names: Vec<_> = T::names().collect();
        for (i, v) in T::ALL.iter().enumerate() {
            assert_eq!(T::from_name(v.name()), Some(*v));
            assert!(!names[..i].contains(&v.name()), "{} named twice", v.name());
        }
        assert_eq!(T::from_name("no-such-value"), None);
    }

    #[test]
    fn names_are_unique_and_round_trip() {
        round_trips::<Method>();
        round_trips::<Solver>();
        round_trips::<RlStop>();
        round_trips::<PnpStop>();
        round_trips::<Boundary>();
        round_trips::<SheetScale>();
        assert_eq!(Solver::from_name("admm-lbfgs"), Some(Solver::AdmmLbfgs));
        assert_eq!(Method::from_name("rl-sum"), Some(Method::RlSum));
    }
}
