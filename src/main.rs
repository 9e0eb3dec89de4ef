/// mimalloc: reuses freed pages across frames instead of returning them to the kernel.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    std::process::exit(lidar_noise::cli::main());
}
