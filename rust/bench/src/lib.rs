//! binpick's criterion benchmarks: the bench targets of this crate are `benches/*.rs` at the
//! repository root (`cargo bench -p binpick-bench`). The library itself is empty.
