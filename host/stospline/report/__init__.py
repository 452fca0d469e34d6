"""What a person reads: the design summary text (`summary_text`) and figures (`plot`)."""
