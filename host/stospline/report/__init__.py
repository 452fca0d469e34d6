"""What a person or a script reads: the JSON summaries of a design and of a Monte Carlo run with
its verdict (`design_summary`, `simulation_summary`), their text (`summary_text`), figures
(`plot`) and the HTML page (`html`)."""
