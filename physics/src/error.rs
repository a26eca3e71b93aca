//! Errors for invalid physical parameters.

/// A physical parameter that cannot be used, with the field it came from.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid {field} = {value}: {reason}")]
pub struct ParamError {
    /// Name of the offending field as the user spells it (e.g. `mu_a_per_cm`).
    pub field: &'static str,
    /// The rejected value, printed as given.
    pub value: String,
    /// Why the value is rejected.
    pub reason: String,
}

impl ParamError {
    /// Builds an error for `field` holding `value`.
    pub fn new(field: &'static str, value: impl ToString, reason: impl Into<String>) -> Self {
        Self {
            field,
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// Rejects a non-finite value.
pub(crate) fn finite(field: &'static str, value: f64) -> Result<f64, ParamError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ParamError::new(field, value, "must be a finite number"))
    }
}

/// Rejects a non-finite or negative value.
pub(crate) fn non_negative(field: &'static str, value: f64) -> Result<f64, ParamError> {
    finite(field, value)?;
    if value < 0.0 {
        return Err(ParamError::new(field, value, "must not be negative"));
    }
    Ok(value)
}

/// Rejects a non-finite, zero or negative value.
pub(crate) fn positive(field: &'static str, value: f64) -> Result<f64, ParamError> {
    finite(field, value)?;
    if value <= 0.0 {
        return Err(ParamError::new(field, value, "must be greater than zero"));
    }
    Ok(value)
}
