from svgf_cli.cli import main

main()
