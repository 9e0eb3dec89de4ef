/// mimalloc: reuses freed pages across frames instead of returning them to the kernel.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    // First, before the heap grows (see the function for why).
    lidar_noise::memory::no_transparent_huge_pages();
    // mimalloc hands a worker's freed warm-up block back to that worker (see the function).
    lidar_noise::memory::warm_worker_heaps(12 << 20);
    std::process::exit(lidar_noise::cli::main());
}
