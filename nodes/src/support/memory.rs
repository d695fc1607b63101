//! Memory budgets: a node that is about to allocate something large checks it here first, so a
//! request the machine cannot hold is refused with the size it needs instead of being killed.

use mesoflow_runtime::NodeError;

/// The budget in bytes: the node's `memory_budget_gb` parameter, else `MESOFLOW_MEMORY_BUDGET_GB`,
/// else 80% of physical memory (unbounded where that cannot be read).
pub fn budget_bytes(param_gb: Option<f64>) -> u64 {
    let env = std::env::var("MESOFLOW_MEMORY_BUDGET_GB")
        .ok()
        .and_then(|v| v.parse::<f64>().ok());
    match param_gb.or(env) {
        Some(gb) => (gb.max(0.0) * 1e9) as u64,
        None => physical_bytes().map_or(u64::MAX, |b| b / 5 * 4),
    }
}

fn physical_bytes() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// `Err` naming the parameter when `bytes` for `what` exceed the budget.
pub fn check(bytes: u64, what: &str, param_gb: Option<f64>) -> Result<(), NodeError> {
    let budget = budget_bytes(param_gb);
    if bytes <= budget {
        return Ok(());
    }
    Err(NodeError::param(
        "memory_budget_gb",
        format!(
            "{what} needs {:.2} GB, over the memory budget of {:.2} GB (set `memory_budget_gb` or MESOFLOW_MEMORY_BUDGET_GB to change it, or crop/downsample/subset the input)",
            bytes as f64 / 1e9,
            budget as f64 / 1e9
        ),
    ))
}

/// `Err` naming `param` (the parameter whose value asks for the memory) when `bytes` for `what`
/// exceed the budget of `MESOFLOW_MEMORY_BUDGET_GB` (else 80% of physical memory). For nodes
/// without a `memory_budget_gb` parameter of their own.
pub fn check_param(bytes: u64, what: &str, param: &str) -> Result<(), NodeError> {
    let budget = budget_bytes(None);
    if bytes <= budget {
        return Ok(());
    }
    Err(NodeError::param(
        param,
        format!(
            "{what} needs {:.2} GB, over the memory budget of {:.2} GB (lower `{param}`, or set MESOFLOW_MEMORY_BUDGET_GB)",
            bytes as f64 / 1e9,
            budget as f64 / 1e9
        ),
    ))
}

/// `a · b · …` in u64, saturating: sizes computed from user parameters must not wrap.
pub fn product(factors: &[u64]) -> u64 {
    factors.iter().fold(1u64, |acc, f| acc.saturating_mul(*f))
}

#[cfg(test)]
mod tests {
    #[test]
    fn over_budget_requests_name_their_size() {
        let e = super::check(3_000_000_000, "the BTF", Some(1.0)).unwrap_err();
        assert!(e.to_string().contains("needs 3.00 GB"), "{e}");
        assert!(e.to_string().contains("budget of 1.00 GB"), "{e}");
        assert!(super::check(999_999_999, "x", Some(1.0)).is_ok());
    }
}
