//! The monitor's numbers written as the messages have always written them: Python's `g`
//! format (`{x:.6g}`), so that a message reads the same whichever layer writes it.

/// `x` with `precision` significant digits in the `g` style of C's printf and Python's
/// format: fixed notation for decimal exponents −4 ≤ e < precision, else `d.ddde±XX`;
/// trailing zeros (and a trailing point) removed; `inf`, `-inf`, `nan`.
pub fn format_g(x: f64, precision: usize) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf" } else { "-inf" }.into();
    }
    let p = precision.max(1);
    // the decimal exponent after rounding to p significant digits
    let sci = format!("{:.*e}", p - 1, x);
    let (mantissa, exp) = sci.split_once('e').expect("an exponent");
    let exp: i32 = exp.parse().expect("an integer exponent");
    if (-4..p as i32).contains(&exp) {
        let decimals = (p as i32 - 1 - exp) as usize;
        trim_zeros(format!("{x:.decimals$}"))
    } else {
        let sign = if exp < 0 { '-' } else { '+' };
        format!(
            "{}e{sign}{:02}",
            trim_zeros(mantissa.to_string()),
            exp.abs()
        )
    }
}

fn trim_zeros(s: String) -> String {
    if !s.contains('.') {
        return s;
    }
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

#[cfg(test)]
mod tests {
    use super::format_g;

    #[test]
    fn numbers_read_as_python_writes_them() {
        // each right-hand side is Python's f"{x:.{p}g}"
        let cases: [(f64, usize, &str); 18] = [
            (97.41234567, 6, "97.4123"),
            (85.0, 6, "85"),
            (48.0, 6, "48"),
            (1e-6, 6, "1e-06"),
            (0.001, 6, "0.001"),
            (0.1, 6, "0.1"),
            (0.00012345678, 6, "0.000123457"),
            (0.000012345678, 6, "1.23457e-05"),
            (1234567.0, 6, "1.23457e+06"),
            (123456.0, 6, "123456"),
            (9.9999996, 6, "10"),
            (-0.0, 6, "-0"),
            (0.0, 3, "0"),
            (0.1234, 3, "0.123"),
            (-2.5e-9, 4, "-2.5e-09"),
            (1.5e300, 3, "1.5e+300"),
            // exact ties round half to even
            (0.125, 2, "0.12"),
            (2.5, 1, "2"),
        ];
        for (x, p, want) in cases {
            assert_eq!(format_g(x, p), want, "{x} .{p}g");
        }
        assert_eq!(format_g(f64::NAN, 6), "nan");
        assert_eq!(format_g(f64::NEG_INFINITY, 6), "-inf");
    }
}
