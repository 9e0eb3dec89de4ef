fn main() {
    std::process::exit(lidar_noise::cli::main());
}
