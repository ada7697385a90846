//! Values and `${...}` expressions, with Python's meaning (xacro evaluates them with Python's
//! `eval`). The expression language is `pyisheval`'s Python subset (arithmetic, comparisons,
//! `and`/`or`/`not`, `x if c else y`, `in`, strings, lists, lambdas); this module adds what
//! xacro's global symbols add (`pi`, `radians`, the rest of `math`) and converts values the
//! way xacro's property table does.

use pyisheval::{EvalError, Interpreter, Value as Py};
use std::collections::HashMap;

/// A property's or an expression's value, typed as xacro types them.
#[derive(Clone, Debug)]
pub(crate) enum Value {
    Int(i64),
    Float(f64),
    Bool(bool),
    Str(String),
    /// Lists, dicts, `None`, lambdas: kept as the evaluator made them.
    Other(Py),
}

impl Value {
    /// A text read from XML, typed as xacro's `Table._eval_literal` does: `'quoted'` is a
    /// string without its quotes, then an int, a float, a boolean word, else the text.
    pub fn literal(s: String) -> Value {
        if s.len() >= 2 && s.starts_with('\'') && s.ends_with('\'') {
            return Value::Str(s[1..s.len() - 1].to_string());
        }
        // Python drops underscores in number literals; xacro keeps such text a string.
        if s.contains('_') {
            return Value::Str(s);
        }
        let t = s.trim();
        if let Ok(i) = t.parse::<i64>() {
            return Value::Int(i);
        }
        if let Some(f) = py_float(t) {
            return Value::Float(f);
        }
        match s.as_str() {
            "true" | "True" => Value::Bool(true),
            "false" | "False" => Value::Bool(false),
            _ => Value::Str(s),
        }
    }

    /// The value as xacro writes it into XML (Python's `str`).
    pub fn to_text(&self) -> String {
        match self {
            Value::Int(i) => i.to_string(),
            Value::Float(f) => py_float_repr(*f),
            Value::Bool(b) => if *b { "True" } else { "False" }.into(),
            Value::Str(s) => s.clone(),
            Value::Other(Py::StringLit(s) | Py::Var(s)) => s.clone(),
            Value::Other(Py::Number(n)) => number_text(*n),
            Value::Other(v) => v.to_string(),
        }
    }

    /// The value of an `xacro:if`/`unless` condition, as xacro's `get_boolean_value`: the
    /// words true/false, an integer, or any non-string value's truth.
    pub fn condition(&self) -> Option<bool> {
        match self {
            Value::Str(s) => match s.as_str() {
                "true" | "True" => Some(true),
                "false" | "False" => Some(false),
                _ => s.trim().parse::<i64>().ok().map(|i| i != 0),
            },
            Value::Int(i) => Some(*i != 0),
            Value::Float(f) => Some(*f != 0.0),
            Value::Bool(b) => Some(*b),
            Value::Other(v) => Some(v.to_bool()),
        }
    }

    fn to_py(&self) -> Py {
        match self {
            Value::Int(i) => Py::Number(*i as f64),
            Value::Float(f) => Py::Number(*f),
            Value::Bool(b) => Py::Number(if *b { 1.0 } else { 0.0 }),
            Value::Str(s) => Py::StringLit(s.clone()),
            Value::Other(v) => v.clone(),
        }
    }

    fn from_py(v: Py) -> Value {
        match v {
            Py::Number(n) if n.fract() == 0.0 && n.abs() < 1e15 => Value::Int(n as i64),
            Py::Number(n) => Value::Float(n),
            Py::StringLit(s) | Py::Var(s) => Value::Str(s),
            other => Value::Other(other),
        }
    }
}

/// Python's `float(text)` for what Rust's parser also reads (`1e-3`, `.5`, `inf`, `nan`).
fn py_float(t: &str) -> Option<f64> {
    let lower = t.to_ascii_lowercase();
    let body = lower.trim_start_matches(['+', '-']);
    // Rust reads "infinity"/"inf"/"nan" like Python; both refuse other words.
    if body.is_empty()
        || !(body.starts_with(|c: char| c.is_ascii_digit() || c == '.') || ["inf", "infinity", "nan"].contains(&body))
    {
        return None;
    }
    lower.parse::<f64>().ok()
}

/// A whole number without a fraction, anything else as Python's `repr(float)`. The
/// evaluator does not tell ints from floats, so `${n + 1}` writes `3` (as Python does for
/// an int) and `${10 / 4}` writes `2.5`; only a float that happens to be whole (`${4 / 2}`,
/// Python's `2.0`) is written differently, with the same number.
fn number_text(n: f64) -> String {
    if n.fract() == 0.0 && n.abs() < 1e15 { format!("{}", n as i64) } else { py_float_repr(n) }
}

/// Python's `repr` of a float: the shortest text that reads back the same, in positional
/// notation for exponents -4..16 (with `.0` when whole), else as `1.5e-05`.
pub(crate) fn py_float_repr(f: f64) -> String {
    if f.is_nan() {
        return "nan".into();
    }
    if f.is_infinite() {
        return if f > 0.0 { "inf" } else { "-inf" }.into();
    }
    if f == 0.0 {
        return if f.is_sign_negative() { "-0.0" } else { "0.0" }.into();
    }
    // Rust's `{:e}` gives the shortest round-trip digits: "1.5e-5", "3e0".
    let sci = format!("{f:e}");
    let (mantissa, exp) = sci.split_once('e').expect("{:e} always has an exponent");
    let exp: i32 = exp.parse().expect("{:e} exponent is an integer");
    if (-4..16).contains(&exp) {
        let s = format!("{f}");
        if s.contains('.') { s } else { s + ".0" }
    } else {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{mantissa}e{sign}{:02}", exp.abs())
    }
}

/// A piece of attribute or text content.
#[derive(Debug, PartialEq)]
pub(crate) enum Segment<'a> {
    Text(&'a str),
    /// `${...}`: the expression inside.
    Expr(&'a str),
    /// `$(...)`: the substitution inside.
    Subst(&'a str),
}

/// Splits text as xacro's lexer does: `$${` and `$$(` are an escaped `${`/`$(`, `${...}`
/// ends at the first `}`, `$(...)` at the first `)`. `Err` names the unclosed piece.
pub(crate) fn segments(text: &str) -> Result<Vec<Segment<'_>>, String> {
    let mut out = Vec::new();
    let mut rest = text;
    while !rest.is_empty() {
        let Some(i) = rest.find('$') else {
            out.push(Segment::Text(rest));
            break;
        };
        if i > 0 {
            out.push(Segment::Text(&rest[..i]));
            rest = &rest[i..];
        }
        let dollars = rest.len() - rest.trim_start_matches('$').len();
        let after = &rest[dollars..];
        if dollars > 1 && (after.starts_with('{') || after.starts_with('(')) {
            // One `$` is dropped: `$${x}` is the text `${x}`.
            let end = dollars + 1;
            out.push(Segment::Text(&rest[1..end]));
            rest = &rest[end..];
        } else if dollars == 1 && (after.starts_with('{') || after.starts_with('(')) {
            let close = if after.starts_with('{') { '}' } else { ')' };
            let Some(j) = after.find(close) else {
                return Err(format!("`{rest}` is not closed (no `{close}`)"));
            };
            let inner = &after[1..j];
            out.push(if close == '}' { Segment::Expr(inner) } else { Segment::Subst(inner) });
            rest = &after[j + 1..];
        } else {
            out.push(Segment::Text(&rest[..dollars]));
            rest = after;
        }
    }
    Ok(out)
}

/// Python keywords and the evaluator's own names, never looked up as properties.
const KEYWORDS: &[&str] = &["and", "or", "not", "if", "else", "in", "is", "lambda", "for", "None", "True", "False"];

/// The identifiers an expression uses (outside string literals, not after a `.`), so that
/// only those properties are evaluated (xacro evaluates properties lazily).
pub(crate) fn names(expr: &str) -> Vec<&str> {
    let b = expr.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == b'\'' || c == b'"' {
            i += 1;
            while i < b.len() && b[i] != c {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
        } else if c.is_ascii_alphabetic() || c == b'_' {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                i += 1;
            }
            let after_dot = expr[..start].trim_end().ends_with('.');
            let word = &expr[start..i];
            if !after_dot && !KEYWORDS.contains(&word) {
                out.push(word);
            }
        } else if c.is_ascii_digit() {
            // A number, with its exponent (`1e5` is not the name `e5`).
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'.') {
                i += if (b[i] == b'e' || b[i] == b'E') && i + 1 < b.len() && matches!(b[i + 1], b'+' | b'-') {
                    2
                } else {
                    1
                };
            }
        } else {
            i += 1;
        }
    }
    out
}

/// Names xacro puts in every expression besides the evaluator's builtins: `math`'s constants
/// and functions (xacro exposes them directly and as `math.NAME`).
fn math_symbol(name: &str) -> Option<Py> {
    let f = |func: fn(&[f64]) -> Result<f64, EvalError>| Some(Py::Builtin { name: name.to_string(), func });
    fn one(a: &[f64], op: fn(f64) -> f64) -> Result<f64, EvalError> {
        match a {
            [x] => Ok(op(*x)),
            _ => Err(EvalError::ArgError(format!("expected 1 argument, got {}", a.len()))),
        }
    }
    fn two(a: &[f64], op: fn(f64, f64) -> f64) -> Result<f64, EvalError> {
        match a {
            [x, y] => Ok(op(*x, *y)),
            _ => Err(EvalError::ArgError(format!("expected 2 arguments, got {}", a.len()))),
        }
    }
    match name {
        "pi" => Some(Py::Number(std::f64::consts::PI)),
        "e" => Some(Py::Number(std::f64::consts::E)),
        "tau" => Some(Py::Number(std::f64::consts::TAU)),
        "inf" => Some(Py::Number(f64::INFINITY)),
        "nan" => Some(Py::Number(f64::NAN)),
        "tan" => f(|a| one(a, f64::tan)),
        "asin" => f(|a| one(a, f64::asin)),
        "acos" => f(|a| one(a, f64::acos)),
        "sinh" => f(|a| one(a, f64::sinh)),
        "cosh" => f(|a| one(a, f64::cosh)),
        "tanh" => f(|a| one(a, f64::tanh)),
        "exp" => f(|a| one(a, f64::exp)),
        "log10" => f(|a| one(a, f64::log10)),
        "log2" => f(|a| one(a, f64::log2)),
        "trunc" => f(|a| one(a, f64::trunc)),
        "radians" => f(|a| one(a, f64::to_radians)),
        "degrees" => f(|a| one(a, f64::to_degrees)),
        "copysign" => f(|a| two(a, f64::copysign)),
        // Python's int() truncates towards zero and round() rounds halves to even (the
        // evaluator's own floor and half-away-from-zero differ for negatives and halves).
        "int" => f(|a| one(a, f64::trunc)),
        "round" => f(|a| match a {
            [x] => Ok(x.round_ties_even()),
            [x, n] => {
                let k = 10f64.powi(*n as i32);
                Ok((x * k).round_ties_even() / k)
            }
            _ => Err(EvalError::ArgError(format!("round expects 1 or 2 arguments, got {}", a.len()))),
        }),
        "fmod" => f(|a| two(a, |x, y| x % y)),
        "log" => f(|a| match a {
            [x] => Ok(x.ln()),
            [x, base] => Ok(x.ln() / base.ln()),
            _ => Err(EvalError::ArgError(format!("log expects 1 or 2 arguments, got {}", a.len()))),
        }),
        _ => None,
    }
}

/// Evaluates a Python expression. `lookup` gives a property's value (evaluating it if it
/// was lazy) or `None` when no property has that name. `Err` is a message for the user.
pub(crate) fn eval_python(
    interp: &Interpreter,
    expr: &str,
    lookup: &mut dyn FnMut(&str) -> Result<Option<Value>, String>,
) -> Result<Value, String> {
    // `math.pi`, `python.len`: xacro's namespaces of its global symbols.
    let code = strip_namespaces(expr);
    let mut context: HashMap<String, Py> = HashMap::new();
    for name in names(&code) {
        if context.contains_key(name) {
            continue;
        }
        if name == "xacro" {
            return Err("xacro's expression helpers (`xacro.load_yaml`, `xacro.arg`, ...) are not supported".into());
        }
        if let Some(v) = lookup(name)? {
            context.insert(name.to_string(), v.to_py());
        } else if let Some(v) = math_symbol(name) {
            context.insert(name.to_string(), v);
        }
    }
    interp.eval_with_context(code.trim(), &context).map(Value::from_py).map_err(|e| match e {
        EvalError::UndefinedVar(v) => format!("name '{v}' is not defined"),
        EvalError::ParseError(m) => format!("not an expression rlnav can evaluate ({m})"),
        other => other.to_string(),
    })
}

/// Removes `math.` and `python.` in front of names (outside strings).
fn strip_namespaces(expr: &str) -> String {
    let mut out = String::with_capacity(expr.len());
    let mut quote: Option<char> = None;
    let mut chars = expr.char_indices().peekable();
    while let Some((i, c)) = chars.next() {
        match quote {
            Some(q) => {
                out.push(c);
                if c == '\\' {
                    if let Some((_, n)) = chars.next() {
                        out.push(n);
                    }
                } else if c == q {
                    quote = None;
                }
            }
            None if c == '\'' || c == '"' => {
                quote = Some(c);
                out.push(c);
            }
            None => {
                let prev_ident = out.chars().last().is_some_and(|p| p.is_alphanumeric() || p == '_' || p == '.');
                let rest = &expr[i..];
                let ns = ["math.", "python."].into_iter().find(|ns| rest.starts_with(ns));
                match ns {
                    Some(ns) if !prev_ident => {
                        for _ in 1..ns.len() {
                            chars.next();
                        }
                    }
                    _ => out.push(c),
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_are_typed_as_xacro_types_them() {
        assert!(matches!(Value::literal("640".into()), Value::Int(640)));
        assert!(matches!(Value::literal(" -2 ".into()), Value::Int(-2)));
        assert!(matches!(Value::literal("8.2573504e-01".into()), Value::Float(f) if f == 0.82573504));
        assert!(matches!(Value::literal(".5".into()), Value::Float(f) if f == 0.5));
        assert!(matches!(Value::literal("True".into()), Value::Bool(true)));
        assert!(matches!(Value::literal("'0.5'".into()), Value::Str(s) if s == "0.5"));
        assert!(matches!(Value::literal("1_000".into()), Value::Str(_)));
        assert!(matches!(Value::literal("base_link".into()), Value::Str(_)));
        assert!(matches!(Value::literal("information".into()), Value::Str(_)));
        assert!(matches!(Value::literal("".into()), Value::Str(s) if s.is_empty()));
    }

    #[test]
    fn floats_print_as_python_prints_them() {
        for (f, s) in [
            (0.03, "0.03"),
            (1.0, "1.0"),
            (-std::f64::consts::FRAC_PI_2, "-1.5707963267948966"),
            (1e-5, "1e-05"),
            (0.0001, "0.0001"),
            (1e16, "1e+16"),
            (123456789012345.6, "123456789012345.6"),
            (0.1 + 0.2, "0.30000000000000004"),
        ] {
            assert_eq!(py_float_repr(f), s);
        }
    }

    #[test]
    fn text_splits_like_xacros_lexer() {
        use Segment::*;
        assert_eq!(
            segments("a ${x*2} $(arg y)$$ {z} $${w} $").unwrap(),
            vec![
                Text("a "),
                Expr("x*2"),
                Text(" "),
                Subst("arg y"),
                Text("$$"),
                Text(" {z} "),
                Text("${"),
                Text("w} "),
                Text("$")
            ]
        );
        assert!(segments("${open").unwrap_err().contains("not closed"));
    }

    #[test]
    fn names_skip_strings_attributes_keywords_and_exponents() {
        assert_eq!(names("a + 'b c' * f(d.e) if not x else 1e-5 + y2"), vec!["a", "f", "d", "x", "y2"]);
        assert_eq!(strip_namespaces("math.pi + 'math.x' + amath.y"), "pi + 'math.x' + amath.y");
    }

    #[test]
    fn expressions_evaluate_with_properties_and_math() {
        let interp = Interpreter::new();
        let mut props = |n: &str| -> Result<Option<Value>, String> {
            Ok(match n {
                "cm2m" => Some(Value::Float(0.01)),
                "gazebo" => Some(Value::Str("classic".into())),
                "n" => Some(Value::Int(3)),
                _ => None,
            })
        };
        let ev = |e: &str, p: &mut dyn FnMut(&str) -> Result<Option<Value>, String>| eval_python(&interp, e, p);
        assert_eq!(ev("23.3*cm2m/2", &mut props).unwrap().to_text(), "0.1165");
        assert_eq!(ev("-pi/2", &mut props).unwrap().to_text(), "-1.5707963267948966");
        assert_eq!(ev("math.radians(180)", &mut props).unwrap().to_text(), "3.141592653589793");
        assert_eq!(ev("n - 1", &mut props).unwrap().to_text(), "2");
        assert_eq!(ev("2**3 + 7 % 4", &mut props).unwrap().to_text(), "11");
        assert_eq!(ev("gazebo == 'classic'", &mut props).unwrap().condition(), Some(true));
        assert_eq!(ev("'a' if n > 5 else 'b'", &mut props).unwrap().to_text(), "b");
        assert_eq!(ev("gazebo + '_x'", &mut props).unwrap().to_text(), "classic_x");
        assert!(ev("undefined_thing * 2", &mut props).unwrap_err().contains("'undefined_thing' is not defined"));
        assert!(ev("xacro.load_yaml('f.yaml')", &mut props).unwrap_err().contains("not supported"));
    }
}
