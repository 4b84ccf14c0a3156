// scan_sums: second step of the prefix sum, in one workgroup: the block sums
// become each block's exclusive offset, and the grand total goes after them
// (sums[count]).

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read_write> sums: array<u32>;

var<workgroup> partial: array<u32, GROUP>;

@compute @workgroup_size(GROUP)
fn main(@builtin(local_invocation_index) t: u32) {
    let n = params.count;
    let chunk = (n + GROUP - 1u) / GROUP;
    let start = min(t * chunk, n);
    let end = min(start + chunk, n);
    var s = 0u;
    for (var i = start; i < end; i++) {
        s += sums[i];
    }
    partial[t] = s;
    workgroupBarrier();
    if (t == 0u) {
        var running = 0u;
        for (var k = 0u; k < GROUP; k++) {
            let v = partial[k];
            partial[k] = running;
            running += v;
        }
        sums[n] = running;
    }
    workgroupBarrier();
    var running = partial[t];
    for (var i = start; i < end; i++) {
        let v = sums[i];
        sums[i] = running;
        running += v;
    }
}
