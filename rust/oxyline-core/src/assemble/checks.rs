//! Value checks shared by the assembly steps: a bad value is a typed error naming the element,
//! the key and the value as the user wrote it.

use crate::error::{Error, Result};

/// A value as users write it: plain for ordinary magnitudes, exponent form for tiny or huge
/// ones (`{}` prints 1e-12 as 0.000000000001).
pub(crate) fn num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

pub(crate) fn check_positive(element: &str, key: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        return Err(Error::model(
            element,
            format!("{key} must be a finite number > 0, got {}", num(v)),
        ));
    }
    Ok(())
}

pub(crate) fn check_nonnegative(element: &str, key: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(Error::model(
            element,
            format!("{key} must be a finite number >= 0, got {}", num(v)),
        ));
    }
    Ok(())
}

/// A value any finite number may take (a volume offset, a time, a coefficient of any sign).
pub(crate) fn check_finite(element: &str, key: &str, v: f64) -> Result<()> {
    if !v.is_finite() {
        return Err(Error::model(
            element,
            format!("{key} must be finite, got {v}"),
        ));
    }
    Ok(())
}
