//! REAL32 and REAL64 values as CANopenNode's gateway shows them: with C's `printf("%g")`
//! (ISO/IEC 9899 §7.21.6.1), a REAL32 first widened to double as C's variadic call does.

/// The significant digits of `%g` without a precision (ISO/IEC 9899 §7.21.6.1: 6).
const DIGITS: usize = 6;

/// `x` as C's `printf("%g", x)` writes it: 6 significant digits, the `%e` style
/// (`1e+08`, an exponent of at least two digits) when the exponent is below −4 or not below
/// 6, else the `%f` style, trailing zeros and a trailing point removed; `-0`, `inf`, `-inf`,
/// `nan` and `-nan` (glibc shows the sign of a NaN).
pub(crate) fn printf_g(x: f64) -> String {
    if x.is_nan() {
        return if x.is_sign_negative() { "-nan" } else { "nan" }.into();
    }
    if x.is_infinite() {
        return if x < 0.0 { "-inf" } else { "inf" }.into();
    }
    if x == 0.0 {
        return if x.is_sign_negative() { "-0" } else { "0" }.into();
    }
    // The exponent X the `%e` style has with DIGITS − 1 decimals, after its rounding: it
    // chooses the style (§7.21.6.1 ¶8).
    let e = format!("{:.*e}", DIGITS - 1, x);
    let (mantissa, exp) = e.split_once('e').unwrap_or((e.as_str(), "0"));
    let exp: i64 = exp.parse().unwrap_or(0);
    if (-4..DIGITS as i64).contains(&exp) {
        // `%f` with DIGITS − 1 − X decimals.
        let decimals = usize::try_from(DIGITS as i64 - 1 - exp).unwrap_or(0);
        trim_zeros(&format!("{x:.decimals$}")).to_owned()
    } else {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim_zeros(mantissa), exp.unsigned_abs())
    }
}

/// Without the zeros that end the fraction, and without the point if nothing is left of it.
fn trim_zeros(number: &str) -> &str {
    if number.contains('.') {
        number.trim_end_matches('0').trim_end_matches('.')
    } else {
        number
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The results of glibc's `printf("%g", x)` for each `x`.
    #[test]
    fn reals_are_written_as_c_printf_g_writes_them() {
        let cases: &[(f64, &str)] = &[
            (f64::from(core::f32::consts::PI), "3.14159"),
            (1e300, "1e+300"),
            (100_000_000.0, "1e+08"),
            (0.0001, "0.0001"),
            (0.00001, "1e-05"),
            (-0.0, "-0"),
            (0.0, "0"),
            (f64::NAN, "nan"),
            (-f64::NAN, "-nan"),
            (f64::INFINITY, "inf"),
            (f64::NEG_INFINITY, "-inf"),
            // Ties on an exact binary value round to even, as glibc does.
            (1_234_565.0, "1.23456e+06"),
            (1_234_575.0, "1.23458e+06"),
            // Rounding carries into the exponent and so changes the style.
            (999_999.5, "1e+06"),
            (9_999_995.0, "1e+07"),
            (0.000_099_999_95, "0.0001"),
            (0.000_123_456_789, "0.000123457"),
            (123_456.0, "123456"),
            (1_234_567.0, "1.23457e+06"),
            (999_999.4, "999999"),
            (1e-300, "1e-300"),
            (5e-324, "4.94066e-324"),
            (f64::MAX, "1.79769e+308"),
            (100.0, "100"),
            (f64::from(0.1_f32), "0.1"),
            (16_777_216.0, "1.67772e+07"),
            (f64::from(f32::MAX), "3.40282e+38"),
            (f64::from(1e-45_f32), "1.4013e-45"),
            (1e15, "1e+15"),
            (123.456, "123.456"),
            (-2.5, "-2.5"),
        ];
        for (x, c) in cases {
            assert_eq!(printf_g(*x), *c, "{x:e}");
        }
    }
}
